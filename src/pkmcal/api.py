"""The public Python API: what a notebook or a script needs, one function per step.

``import pkmcal`` gives these names (imported on first use, so that ``import pkmcal`` stays
cheap). Units as everywhere in pkmcal: objects hold mm and radians; files and tables are in
mm and degrees; pose x, y, z, a, b, c with R = Rz(c)·Ry(b)·Rx(a) (:mod:`pkmcal.conventions`).

A campaign from planning to export (docs/api.md has more)::

    >>> import pkmcal
    >>> machine = pkmcal.load_machine("stewart-prototype")
    >>> setup = pkmcal.load_setup("full-pose-paper1", machine)
    >>> plan = pkmcal.plan(machine, setup, 30, seed=1, n_candidates=500)
    >>> real = pkmcal.load_machine("stewart-prototype-real")   # or pkmcal.perturb(machine, 0.5, seed=2)
    >>> sim = pkmcal.simulate(machine, real, setup, plan.poses, seed=3)
    >>> result = pkmcal.identify(machine, setup, sim.measurements)
    >>> result.success, len(result.parameters) == len(result.names)
    (True, True)
    >>> check = pkmcal.verify(result.mechanism, real, plan.poses[:10], nominal=machine)
    >>> figures = check.to_dict()
    >>> figures["after"]["position_max_mm"] < figures["before"]["position_max_mm"]
    True
    >>> print(pkmcal.export(result.mechanism, "linuxcnc").splitlines()[0])  # doctest: +ELLIPSIS
    # genhexkins configuration for machine 'stewart-prototype', written by pkmcal ...
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from pkmcal.identification.engine import IdentificationResult
    from pkmcal.identification.identifiability import IdentifiabilityReport
    from pkmcal.identification.simulation import SimulationResult
    from pkmcal.identification.verification import VerificationReport
    from pkmcal.io.measurements import Measurements
    from pkmcal.mechanisms.base import Mechanism
    from pkmcal.planning.plan import Plan
    from pkmcal.sensors.base import MeasurementSetup

#: Formats of :func:`export` (those of ``pkmcal export --format``).
EXPORT_FORMATS = ("linuxcnc", "linuxcnc-ini", "json", "klipper", "marlin")


def load_machine(spec: str | os.PathLike) -> Mechanism:
    """A machine from a machine file (YAML, any kind) or a built-in name (``pkmcal machines``).

    >>> import pkmcal
    >>> pkmcal.load_machine("kossel-mini").kind
    'linear-delta'
    """
    from pkmcal.io.lookup import load_machine as _load

    return _load(spec)


def save_machine(machine: Mechanism, path: str | os.PathLike) -> None:
    """Write ``machine`` to ``path`` atomically; loading it back gives an equal machine, bit
    for bit (docs/file-formats.md)."""
    from pkmcal.io.machine_file import save_machine as _save

    _save(machine, path)


def load_setup(spec: str | os.PathLike, machine: Mechanism | None = None) -> MeasurementSetup:
    """A measurement setup (sensor, noise, priors) from a setup file or a built-in name,
    bound to ``machine`` when given (checks that the sensor can measure it)."""
    from pkmcal.io.lookup import load_setup as _load

    return _load(spec, machine)


def save_setup(setup: MeasurementSetup, path: str | os.PathLike) -> None:
    """Write ``setup`` to ``path`` atomically (reads back equal)."""
    from pkmcal.io.setup_file import save_setup as _save

    _save(setup, path)


def load_measurements(path: str | os.PathLike, machine: Mechanism, setup: MeasurementSetup) -> Measurements:
    """The measurement CSV ``path`` (actuator readings, the setup's sensor readings, optional
    commanded poses; docs/file-formats.md) in internal units."""
    from pkmcal.io.measurements import load_measurements as _load

    return _load(path, machine, setup)


def save_measurements(measurements: Measurements, machine: Mechanism, setup: MeasurementSetup,
                      path: str | os.PathLike) -> None:
    """Write ``measurements`` as the CSV that :func:`load_measurements` reads."""
    from pkmcal.io.measurements import save_measurements as _save

    _save(path, measurements, machine, setup)


def plan(machine: Mechanism, setup: MeasurementSetup, n: int, *, algorithm: str = "default",
         seed: int | None = 0, n_candidates: int = 2000, **options) -> Plan:
    """Choose ``n`` poses to measure (``pkmcal plan``; :func:`pkmcal.planning.plan.plan_poses`
    takes the other ``options``). ``plan.poses`` (n, n_dof) internal units, ``plan.commands``
    the nominal actuator commands, ``plan.selection.indices`` O1..O5. A Z probe's points lie
    on the bed (``plan.on_bed``; ``on_bed=False`` plans them anywhere in the volume), and
    :func:`pkmcal.planning.plan.height_sigma` predicts their first-layer error.

    >>> import pkmcal
    >>> m = pkmcal.load_machine("stewart-prototype")
    >>> p = pkmcal.plan(m, pkmcal.load_setup("indicators-prototype", m), 45, seed=1, n_candidates=400)
    >>> p.poses.shape
    (45, 6)
    """
    from pkmcal.planning.plan import plan_poses

    return plan_poses(machine, setup, n, algorithm=algorithm, seed=seed, n_candidates=n_candidates, **options)


def perturb(machine: Mechanism, magnitude_mm: float, seed: int | None = None, *,
            distribution: str = "uniform") -> Mechanism:
    """A random "real" machine: every parameter off by up to ``magnitude_mm`` (uniform) or
    with that std (``distribution="gaussian"``); angles by the same displacement at 1 m."""
    from pkmcal.identification.simulation import perturb_machine

    return perturb_machine(machine, magnitude_mm, seed, distribution=distribution)


def simulate(nominal: Mechanism, real: Mechanism, setup: MeasurementSetup, poses: np.ndarray,
             seed: int | None = None, **options) -> SimulationResult:
    """Simulate measuring ``poses`` on ``real`` commanded through ``nominal`` with the noise
    of ``setup`` (``pkmcal simulate``); ``.measurements`` is what a measured CSV holds, and
    ``.dropped`` says which poses the real machine could not take and why. Every machine: a
    redundantly actuated one settles at static equilibrium under the setup's ``simulation:``
    stiffness and load."""
    from pkmcal.identification.simulation import simulate_campaign

    return simulate_campaign(nominal, real, setup, poses, seed, **options)


def identifiability(machine: Mechanism, setup: MeasurementSetup, poses: np.ndarray,
                    **options) -> IdentifiabilityReport:
    """Which parameters ``setup`` can identify from ``poses`` (rank, the unidentifiable
    combinations, a suggested gauge; ``pkmcal identifiability``).

    >>> import pkmcal
    >>> m = pkmcal.load_machine("stewart-prototype")
    >>> s = pkmcal.load_setup("indicators-prototype", m)
    >>> report = pkmcal.identifiability(m, s, pkmcal.plan(m, s, 45, seed=1, n_candidates=400).poses)
    >>> report.rank, len(report.null_space)
    (39, 3)
    """
    from pkmcal.identification.identifiability import identifiability as _identifiability

    return _identifiability(machine, setup, poses, **options)


def identify(machine: Mechanism, setup: MeasurementSetup, measurements, **options) -> IdentificationResult:
    """Identify the parameters (``pkmcal identify``; the ``options`` of
    :func:`pkmcal.identification.engine.identify`: method, free, fix, loss, reject, priors,
    ...). ``result.mechanism`` is the calibrated machine (with its covariance),
    ``result.sensor`` the identified sensor, ``result.parameters`` one
    :class:`~pkmcal.identification.engine.ParameterEstimate` per parameter in file units.

    A fit that ``pkmcal identify`` would refuse to write
    (:mod:`pkmcal.identification.fit_verdict`: χ² beyond what the noise allows, absurd
    geometry, not converged) is returned with a :class:`~pkmcal.errors.PkmcalWarning` that
    says why; ``result.verdict`` is the verdict on the fit alone (without the readers' notes)."""
    import warnings

    from pkmcal.errors import PkmcalWarning
    from pkmcal.identification.engine import identify as _identify
    from pkmcal.identification.fit_verdict import input_causes, judge
    from pkmcal.io.measurements import Measurements

    result = _identify(machine, setup, measurements, **options)
    causes = input_causes(machine, setup, measurements) if isinstance(measurements, Measurements) else []
    verdict = judge(result, causes)
    if not verdict.acceptable:
        warnings.warn(f"pkmcal identify would refuse this fit: {verdict.with_diagnoses(causes).text()}", PkmcalWarning,
                      stacklevel=2)
    return result


def verify(calibrated: Mechanism, real: Mechanism, poses: np.ndarray, nominal: Mechanism | None = None,
           **options) -> VerificationReport:
    """Pose errors of the ``real`` machine commanded through ``calibrated`` (and ``nominal``
    for "before") on held-out ``poses`` (``pkmcal verify --real``); ``.to_dict()`` the
    figures of ``verify --json``. A redundantly actuated machine needs ``setup=`` (its
    ``simulation:`` stiffness and load) and is compared on what its tracker reads."""
    from pkmcal.identification.verification import verify as _verify

    return _verify(calibrated, real, poses, nominal, **options)


def export(machine: Mechanism, fmt: str) -> str:
    """The text ``pkmcal export --format fmt`` writes: ``linuxcnc`` (genhexkins HAL lines),
    ``linuxcnc-ini`` (the matching INI sections), ``json``, ``klipper`` or ``marlin`` (linear
    deltas; the parameters the firmware cannot hold are dropped:
    :func:`pkmcal.io.delta_firmware.firmware_subset` lists them)."""
    from pkmcal.errors import PkmcalError

    if fmt == "linuxcnc":
        from pkmcal.io.export_linuxcnc import linuxcnc_hal

        return linuxcnc_hal(machine)
    if fmt == "linuxcnc-ini":
        from pkmcal.io.export_linuxcnc import linuxcnc_ini

        return linuxcnc_ini(machine)
    if fmt == "json":
        from pkmcal.io.calibration_json import format_calibration_json

        return format_calibration_json(machine)
    if fmt in ("klipper", "marlin"):
        if machine.kind != "linear-delta":
            raise PkmcalError(f"format '{fmt}' exports linear delta printers; '{machine.name}' is a {machine.kind}")
        from pkmcal.io.delta_firmware import firmware_subset, klipper_text, marlin_text

        fw, _ = firmware_subset(machine)
        return klipper_text(fw) if fmt == "klipper" else marlin_text(fw)
    raise PkmcalError(f"unknown export format '{fmt}'; use one of {', '.join(EXPORT_FORMATS)}")


__all__ = ["EXPORT_FORMATS", "export", "identifiability", "identify", "load_machine", "load_measurements",
           "load_setup", "perturb", "plan", "save_machine", "save_measurements", "save_setup", "simulate", "verify"]
