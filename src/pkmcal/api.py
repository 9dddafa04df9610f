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
import types
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

    from pkmcal.identification.identifiability import IdentifiabilityReport
    from pkmcal.identification.simulation import SimulationResult
    from pkmcal.identification.verification import VerificationReport
    from pkmcal.io.measurements import Measurements
    from pkmcal.mechanisms.base import Mechanism
    from pkmcal.workflow.plan import PosePlan
    from pkmcal.sensors.base import MeasurementSetup
    from pkmcal.workflow.calibration import Calibration

#: Formats of :func:`export` (those of ``pkmcal export --format``; :data:`pkmcal.workflow.export.EXPORT_FORMATS`).
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
         seed: int | None = 0, n_candidates: int = 2000, **options) -> PosePlan:
    """Choose ``n`` poses to measure (``pkmcal plan``; :func:`pkmcal.planning.plan.plan_poses`
    takes the other ``options``). ``plan.poses`` (n, n_dof) internal units, ``plan.commands``
    the nominal actuator commands, ``plan.selection.indices`` O1..O5. A Z probe's points lie
    on the bed (``plan.on_bed``; ``on_bed=False`` plans them anywhere in the volume), and
    :func:`pkmcal.planning.plan.height_sigma` predicts their first-layer error. The plan
    (a :class:`~pkmcal.workflow.plan.PosePlan`) writes what ``pkmcal plan`` writes and prints:
    ``plan.csv(command)`` the pose file, ``plan.printer_file("klipper" | "gcode", ...)`` a Z
    probe's macro or G-code, ``plan.summary(target)`` the summary (``--json``'s keys; a Z
    probe's predicted first-layer error under ``"probe"``).

    >>> import pkmcal
    >>> m = pkmcal.load_machine("stewart-prototype")
    >>> p = pkmcal.plan(m, pkmcal.load_setup("indicators-prototype", m), 45, seed=1, n_candidates=400)
    >>> p.poses.shape, p.summary()["selection"]["n_poses"]
    ((45, 6), 45)
    """
    from pkmcal.planning.plan import plan_poses
    from pkmcal.workflow.plan import PosePlan

    return PosePlan.of(plan_poses(machine, setup, n, algorithm=algorithm, seed=seed, n_candidates=n_candidates,
                                  **options), machine, setup)


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


def _mapping(columns=None, length_unit=None, angle_unit=None, quaternion_order=None):
    """The :class:`~pkmcal.io.import_mapping.ImportMapping` of the command line's ``--columns``,
    ``--length-unit``, ``--angle-unit``, ``--quaternion-order`` (None when none is given)."""
    from pkmcal.io.import_mapping import make_mapping

    return make_mapping(columns, length_unit, angle_unit, quaternion_order)


def identify(machine: Mechanism | str | os.PathLike, setup: MeasurementSetup | str | os.PathLike, measurements, *,
             bad_fit: str = "warn", columns: str | None = None, length_unit: str | None = None,
             angle_unit: str | None = None, quaternion_order: str | None = None, **options) -> Calibration:
    """Identify the parameters (``pkmcal identify``): a :class:`~pkmcal.workflow.Calibration`
    that can ``save`` the calibrated machine file (the bytes of ``pkmcal identify -o``),
    ``verify`` on held-out data, ``export`` to a controller (with the firmware-limited refit)
    and write its ``report``.

    ``machine``, ``setup`` and ``measurements`` are objects or, as on the command line,
    files and built-in names (recorded in the calibration record with their SHA-256; a
    measurement file read with ``columns``, ``length_unit``, ``angle_unit``,
    ``quaternion_order`` as ``--columns`` ...). ``options``: those of
    :func:`pkmcal.workflow.calibrate` (``method``, ``free``, ``fix``, ``priors`` (strings
    ``"L0_*=±1"`` too), ``clipped``, ``merge_setup_free`` (``--free``'s rule: the setup's free
    sensor parameters added), ``name``, ...) and of
    :func:`pkmcal.identification.engine.identify` (``loss``, ``reject``, ``weighted``, ...).
    ``calibration.mechanism`` is the calibrated machine (with its covariance),
    ``calibration.machine`` the same under its new name with its calibration record,
    ``calibration.sensor`` the identified sensor, ``calibration.parameters`` one
    :class:`~pkmcal.identification.engine.ParameterEstimate` per parameter in file units
    (every attribute of the engine's :class:`~pkmcal.identification.engine.IdentificationResult`
    is the calibration's too).

    A fit that ``pkmcal identify`` would refuse to write
    (:mod:`pkmcal.identification.fit_verdict`: χ² beyond what the noise allows, absurd
    geometry, not converged) is returned with a :class:`~pkmcal.errors.PkmcalWarning` that
    says why (``bad_fit="refuse"``: a :class:`~pkmcal.errors.PkmcalError`, as the command);
    ``calibration.verdict`` is the verdict, and the record says it was written although refused."""
    from pkmcal.workflow.calibration import calibrate

    return calibrate(machine, setup, measurements, bad_fit=bad_fit,
                     mapping=_mapping(columns, length_unit, angle_unit, quaternion_order), **options)


def verify(calibrated, real: Mechanism | str | None = None, poses=None, nominal: Mechanism | str | None = None, *,
           heldout=None, setup=None, calibration_measurements=None, clipped: str | None = None,
           columns: str | None = None, length_unit: str | None = None, angle_unit: str | None = None,
           quaternion_order: str | None = None, **options):
    """Validate a calibration on held-out data (``pkmcal verify``).

    * ``heldout``: **measured** held-out data (a measurement file or loaded measurements, not
      used in the fit; read with ``columns`` ... as ``--columns`` ...): each held-out
      measurement predicted from its actuator readings and compared with what was measured,
      before / after / after re-registering the instrument (a
      :class:`~pkmcal.identification.heldout.HeldoutValidation`; ``pkmcal verify
      --held-out``). ``calibrated`` a :class:`~pkmcal.workflow.Calibration` or a
      calibrated machine file (its ``setup:``; else give ``setup``); ``nominal``,
      ``calibration_measurements`` and ``clipped`` as ``--nominal``,
      ``--calibration-measurements``, ``--clipped``.
    * ``real`` and ``poses``: pose errors of the ``real`` machine commanded through
      ``calibrated`` (a machine, a file, or a calibration) and ``nominal`` for "before" on
      held-out ``poses`` (``pkmcal verify --real``; a file of poses or an array in internal
      units); ``.to_dict()`` the figures of ``verify --json``. A redundantly actuated machine
      needs ``setup=`` (its ``simulation:`` stiffness and load) and is compared on what its
      tracker reads; ``options``: :func:`pkmcal.identification.verification.verify`'s."""
    from pkmcal.workflow.calibration import Calibration

    mapping = _mapping(columns, length_unit, angle_unit, quaternion_order)
    given = calibrated
    campaign = given if isinstance(given, Calibration) else None
    if heldout is not None:
        if real is not None or poses is not None:
            from pkmcal.errors import PkmcalError

            raise PkmcalError("verify: give the held-out measurements or a real machine with poses, not both")
        if campaign is not None:
            return campaign.verify(heldout, mapping=mapping, clipped=clipped)
        from pkmcal.workflow.verify import verify_measured

        return verify_measured(calibrated, heldout, nominal=nominal, setup=setup,
                               calibration_measurements=calibration_measurements, clipped=clipped or "drop",
                               mapping=mapping)
    if campaign is not None:
        if nominal is not None:
            options["nominal"] = nominal
        if setup is not None:
            options["setup"] = setup
        return campaign.verify(real=real, poses=poses, **options)
    if any(isinstance(v, (str, os.PathLike)) for v in (given, real, poses)):
        from pkmcal.workflow.verify import verify_against_real

        return verify_against_real(calibrated, real, poses, nominal=nominal, setup=setup, mapping=mapping, **options)
    from pkmcal.identification.verification import verify as _verify

    if setup is not None:
        options["setup"] = setup
    return _verify(calibrated, real, poses, nominal, **options)


def export(machine, fmt: str, **options) -> str:
    """The text ``pkmcal export --format fmt`` writes: ``linuxcnc`` (genhexkins HAL lines),
    ``linuxcnc-ini`` (the matching INI sections), ``json``, ``klipper`` or ``marlin`` (linear
    deltas; Klipper also rotary deltas). ``machine``: a :class:`~pkmcal.workflow.Calibration`,
    a machine, or a machine file / built-in name. A linear delta with what its firmware cannot
    hold (rail leans, a tool offset) is exported as the firmware-limited refit, by default on
    the calibration's own measurements (those the calibration record names, for a machine or
    a file), as ``pkmcal export`` does; ``options``:
    :func:`pkmcal.workflow.export.export_machine`'s (``refit=False`` as ``--no-refit``,
    ``measurements=``, ``heldout=``, ``accept_undetermined=``, ``stroke_margin=``,
    ``klipper_config=``, ...). What the export says to the user (what the firmware cannot
    hold, the refit's report) is :attr:`pkmcal.workflow.export.Exported.notes`, from
    :meth:`pkmcal.workflow.Calibration.export` or :func:`~pkmcal.workflow.export.export_machine`."""
    from pkmcal.workflow.calibration import Calibration
    from pkmcal.workflow.export import export_machine

    given = machine
    if isinstance(given, Calibration):
        return given.export(fmt, **options).text
    return export_machine(machine, fmt, **options).text


def report(calibration: Calibration, folder: str | os.PathLike, heldout=None, **options):
    """Write the HTML calibration report of ``calibration`` (``report.html`` and its figures)
    into ``folder``, as ``pkmcal identify --report`` does; ``heldout``: a held-out validation
    (:func:`verify`'s) or held-out measurements to validate and show. Returns the written
    report (``.html`` the page's path)."""
    return calibration.report(folder, heldout, **options)


def study(spec, output: str | os.PathLike, *, seed: int | None = None, trials: int | None = None,
          workers: int | None = None, dask: str | None = None, resume: bool = False, progress: bool = False,
          figures: bool = True):
    """Run a Monte Carlo study of campaigns (``pkmcal study STUDY.yaml -o RESULTS/``): ``spec``
    a study file or a loaded :class:`~pkmcal.study.schema.StudySpec`; ``seed`` and ``trials``
    override the file's; ``workers`` local processes, ``dask`` a scheduler address or
    ``"local"``. Returns the :class:`~pkmcal.study.runner.StudyResult` (``.summary``,
    ``.columns``), with trials.csv, summary.csv and (``figures``) index.html in ``output``."""
    from pkmcal.errors import PkmcalError
    from pkmcal.study import load_study, run_study

    if workers is not None and dask not in (None, "local"):
        raise PkmcalError("workers applies to local runs and to dask='local'; a Dask scheduler's workers are "
                          "started with 'dask worker'")
    if isinstance(spec, (str, os.PathLike)):
        spec = load_study(spec)
    if seed is not None:
        spec = spec.with_seed(seed)
    if trials is not None:
        if trials < 1:
            raise PkmcalError(f"--trials must be at least 1; got {trials}")
        spec = spec.with_trials(trials)
    return run_study(spec, os.fspath(output), workers=workers, dask=dask, resume=resume, progress=progress,
                     figures=figures)


class CallablePackage(types.ModuleType):
    """The class of the subpackages that are also API functions of their name
    (``pkmcal.report``, ``pkmcal.study``): calling the package calls :func:`report` or
    :func:`study`, so that ``pkmcal.report(...)`` is the API's whether or not the subpackage
    has been imported (importing it makes it the ``pkmcal`` attribute of that name)."""

    def __call__(self, *args, **kwargs):
        return globals()[self.__name__.rsplit(".", 1)[1]](*args, **kwargs)


__all__ = ["EXPORT_FORMATS", "export", "identifiability", "identify", "load_machine", "load_measurements",
           "load_setup", "perturb", "plan", "report", "save_machine", "save_measurements", "save_setup", "simulate",
           "study", "verify"]
