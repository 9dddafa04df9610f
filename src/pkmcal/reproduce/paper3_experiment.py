"""Paper 3 §3 in simulation: the paper's fits by name and the held-out experiment.

:func:`fit_redundant` runs one of :data:`METHODS` by name, every one through
:func:`pkmcal.identification.engine.identify` with ``method="projection"`` and the
engine's automatic gauge (``fix="auto"``: an unidentifiable combination is fixed at its
start by pivoted QR and named in ``identifiability``):

* ``projection`` — weighted; the engine re-solves x_j* = argmin ‖e_j‖ at every iterate
  (Gauss–Newton on the errors-in-variables problem with the poses eliminated;
  :mod:`pkmcal.identification.projection`, paper 3 eq. 5–9);
* ``projection-single`` — the paper's eq. 10: one linear least-squares step, linearised at
  the commanded poses and the nominal parameters (the engine's ``projection-single``);
* ``projection-unweighted`` — rows in raw mm and rad (W = I);
* ``ignore-redundancy``, ``actuator-subset`` — the baselines of paper 3 §1
  (:mod:`pkmcal.identification.baselines`).

:func:`calibration_experiment` is paper 3 §3 in simulation: the real machine settles at
static equilibrium (:func:`~pkmcal.identification.simulation.simulate_campaign`), each
method identifies, and the held-out tool errors of the real machine commanded through each
model are measured (:func:`~pkmcal.identification.tool_errors.tool_errors`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import IdentificationResult
from pkmcal.identification.simulation import SimulationResult, simulate_campaign
from pkmcal.identification.tool_errors import tool_errors
from pkmcal.mechanisms.base import Mechanism
from pkmcal.identification.baselines import BASELINES, identify_by_method
from pkmcal.sensors.base import MeasurementSetup, NoiseModel, Sensor

#: The paper-3 fits :func:`fit_redundant` knows (the reproduction's and benchmark's rows).
METHODS = ("projection", "projection-single", "projection-unweighted") + BASELINES


def fit_redundant(method: str, machine: Mechanism, setup: MeasurementSetup, measurements, free=None,
                  keep=None) -> IdentificationResult:
    """Identify ``machine`` (+ the setup's sensor) from ``measurements`` by the paper-3
    ``method`` (module docstring), through :func:`~pkmcal.identification.engine.identify`
    with the automatic gauge. ``keep``: the actuators (0-based) of ``actuator-subset``."""
    if method not in METHODS:
        raise PkmcalError(f"unknown paper-3 method '{method}'; use one of {', '.join(METHODS)}")
    engine_method = method if method in BASELINES or method == "projection-single" else "projection"
    return identify_by_method(machine, setup, measurements, engine_method, keep, free=free, fix="auto",
                              weighted=method != "projection-unweighted")


@dataclass(frozen=True)
class HeldOutResult:
    """Held-out tool errors (mm) before and after calibration by each method, the fits and
    the simulated calibration campaign."""

    before: np.ndarray
    after: dict[str, np.ndarray]
    fits: dict
    simulation: SimulationResult

    def improvement_pct(self, method: str) -> float:
        """100 (1 − mean(after) / mean(before)) (paper 3 §3.1, §3.2)."""
        return 100.0 * (1.0 - float(np.mean(self.after[method])) / float(np.mean(self.before)))


def calibration_experiment(
    nominal: Mechanism,
    nominal_sensor: Sensor,
    real: Mechanism,
    setup: MeasurementSetup,
    calib_poses: np.ndarray,
    check_poses: np.ndarray,
    rng: np.random.Generator,
    free=None,
    keep=None,
    methods=METHODS,
    weights: NoiseModel | None = None,
    ignore_limits: tuple[str, ...] = ("workspace",),
) -> HeldOutResult:
    """Paper 3 §3 in simulation: measure ``calib_poses`` on ``real`` (``setup``: its true
    sensor, the noise drawn and the actuator stiffness and load of its ``simulation``
    block), identify by each of ``methods`` (:func:`fit_redundant`, starting from
    ``nominal`` and ``nominal_sensor``), command the held-out ``check_poses``' tool points
    y* = h(x_c, θ_nominal) through each model and measure the real tool errors ("before":
    the nominal model). ``weights`` (default the setup's noise) are the standard deviations
    the identification weights its rows with. ``ignore_limits``: the sampled poses lie in
    the nominal workspace box, which the real machine may leave by its errors; reach and
    transmission limits stay checked (a pose that fails them is an error here)."""
    sim = simulate_campaign(nominal, real, setup, calib_poses, rng, ignore_limits)
    if sim.dropped:
        k, why = next(iter(sim.dropped.items()))
        raise PkmcalError(f"calibration pose {k + 1} was not reached by the real machine: {why}")
    fit_setup = MeasurementSetup(nominal_sensor, setup.noise if weights is None else weights)
    fits = {m: fit_redundant(m, nominal, fit_setup, sim.measurements, free, keep) for m in methods}
    for m, f in fits.items():
        if not f.success:
            raise PkmcalError(f"the {m} fit did not converge ({f.message})")

    def held_out(model, model_sensor, name):
        err = tool_errors(model, model_sensor, real, setup, check_poses, name, ignore_limits, nominal_sensor)
        if not err.valid.all():
            k, why = next(iter(err.dropped.items()))
            raise PkmcalError(f"held-out pose {k + 1} was not reached by the real machine ({name}): {why}")
        return err.tool

    return HeldOutResult(before=held_out(nominal, nominal_sensor, "before"),
                         after={m: held_out(f.mechanism, f.sensor, m) for m, f in fits.items()},
                         fits=fits, simulation=sim)
