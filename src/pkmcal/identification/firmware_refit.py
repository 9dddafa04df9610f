"""The firmware-limited refit of a linear delta: the best machine its firmware can hold, and
what dropping the rest costs (issue 13, item 4).

Klipper and Marlin hold ten numbers of a linear delta (:mod:`pkmcal.io.delta_firmware`):
one radius R and, per tower, an angle θ_i, an arm L_i and an endstop E_i. A calibrated
machine may have more (rail leans, per-tower radii, a tool offset). Writing only its ten
numbers ("dropping" the rest) leaves a machine that no longer fits the measurements. The
best machine the firmware can hold is the least-squares fit over its own numbers with the
rest at the firmware's values (vertical rails, no tool offset):

    φ̂ = argmin_φ  Σ_j ‖W_j r_j(θ(φ))‖² + Σ_k ((θ_k − μ_k)/σ_k)²,
    θ(φ): radius_a = radius_b = radius_c = R, angle_i, arm_i, endstop_i free, leans = 0,
          tool = 0,

with the calibration's method, noise weights and priors (the ``calibration`` record of the
machine file). The engine (:func:`pkmcal.identification.engine.identify`) fits the angles,
arms and endstops (and the setup's free sensor parameters, e.g. a bed tilt) at a given R,
with its automatic gauge (a Z probe on a level bed cannot see the towers turned together);
the common radius, which the engine's per-tower parameters cannot tie, is the minimiser of
that fit's cost over R (Brent's method, :func:`scipy.optimize.minimize_scalar`).

The firmware's numbers the calibration held stay held (:func:`refit_free`: the record's
``free``; a delta's arms from Z-probe heights alone), and a refit with no residual left over
for its free numbers (the common radius counted) is an error, not an exact interpolation.

Three models are scored on the same measurements (and on held-out ones when given): the
full calibrated model, the firmware's numbers of it without a refit, and the refit. Each
score is the RMS of the raw residual rows (measured − predicted reading, mm for a Z probe:
the height error of the nozzle where the probe triggered) with the sensor parameters the
setup frees fitted on the fit measurements for that model (so that no model is judged with
another's bed tilt) and held for the held-out ones.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.linear_delta import PARAM_NAMES, TOOL_PARAMS, TOWERS

#: The parameters the firmware's numbers set, besides the common radius.
FIRMWARE_FREE = tuple(f"{p}_{t}" for p in ("angle", "arm", "endstop") for t in TOWERS)
RADII = tuple(f"radius_{t}" for t in TOWERS)
#: Held at the firmware's value (0): what neither Klipper nor Marlin can hold.
HELD = tuple(f"{p}_{t}" for p in ("lean_radial", "lean_tangential") for t in TOWERS) + TOOL_PARAMS


@dataclass(frozen=True)
class Score:
    """One model on the measurements: raw residual RMS per unit ({"mm": rms}) over the
    poses it could solve (``n_fit`` of them; held-out likewise)."""

    label: str
    machine: object
    sensor: object
    fit_rms: dict[str, float]
    n_fit: int
    heldout_rms: dict[str, float] | None = None
    n_heldout: int | None = None

    def to_dict(self) -> dict:
        return {"model": self.label, "fit_rms": self.fit_rms, "n_fit_poses": self.n_fit,
                "heldout_rms": self.heldout_rms, "n_heldout_poses": self.n_heldout}


@dataclass(frozen=True)
class FirmwareRefit:
    """The result of :func:`firmware_refit`: the three scores, the refit machine (the one to
    export), the refit's free parameters, gauge and priors, and notes."""

    full: Score
    dropped: Score
    refit: Score
    free: tuple[str, ...]
    gauge: tuple[str, ...]
    priors: tuple[str, ...]
    method: str
    notes: tuple[str, ...] = ()
    #: the refit's covariance (p, p) of the machine parameters (internal units; zero rows for
    #: held ones; the common radius, fitted outside the engine, is held in it)
    covariance: np.ndarray | None = None

    @property
    def machine(self):
        """The refit machine (the machine itself when the measurements read it as pose pairs)."""
        from pkmcal.mechanisms.pose_pairs import single_machine

        return single_machine(self.refit.machine)

    def lines(self) -> list[str]:
        """The report, one statement per line (``pkmcal export`` prints them on stderr)."""
        def rms(d):
            return ", ".join(f"{v:.4g} {u}" for u, v in d.items()) if d else "n/a"

        out = [f"firmware-limited refit ({self.method}; free: one common radius, {', '.join(self.free)}; "
               f"held at 0: rail leans, tool offset"
               + (f"; gauge held: {', '.join(self.gauge)}" if self.gauge else "")
               + (f"; priors from the calibration: {', '.join(self.priors)}" if self.priors else "") + "):"]
        for s in (self.full, self.dropped, self.refit):
            line = f"  {s.label:<36} fit rms {rms(s.fit_rms)} ({s.n_fit} poses)"
            if s.heldout_rms is not None:
                line += f", held-out rms {rms(s.heldout_rms)} ({s.n_heldout} poses)"
            out.append(line)
        out.extend(f"  note: {n}" for n in self.notes)
        return out

    def to_dict(self) -> dict:
        return {"method": self.method, "free": list(self.free), "common_radius": "radius_a = radius_b = radius_c",
                "held_at_zero": list(HELD), "gauge": list(self.gauge), "priors": list(self.priors),
                "models": [s.to_dict() for s in (self.full, self.dropped, self.refit)],
                "rms_unit": "the unit of the residual rows (mm for a Z probe: measured - predicted reading)",
                "notes": list(self.notes)}


def dropped_machine(machine):
    """The machine the firmware's ten numbers describe (what an export without a refit
    writes: :func:`pkmcal.io.delta_firmware.firmware_subset`, leans and tool offset 0, the
    mean radius), with the reading reference of ``machine`` (so that it reads the same
    measurements)."""
    from pkmcal.io.delta_firmware import firmware_subset
    from pkmcal.mechanisms.pose_pairs import single_machine

    single = single_machine(machine)        # a machine read as pose pairs (printed distances): its own numbers
    return machine.with_params(firmware_subset(single)[0].machine(machine.name).params, name=machine.name)


def recorded_priors(machine) -> tuple:
    """The priors of the machine file's ``calibration`` record (``NAME: 'MEAN ± STD UNIT'``)
    as :class:`~pkmcal.identification.priors.Prior` objects."""
    from pkmcal.identification.priors import parse_value

    record = (machine.metadata or {}).get("calibration") or {}
    out = []
    for name, text in (record.get("priors") or {}).items():
        value = str(text).rsplit(" ", 1)[0] if str(text).endswith((" mm", " deg")) else str(text)
        out.append(parse_value(value, name, f"the calibration record of machine '{machine.name}'",
                               origin="calibration record"))
    return tuple(out)


def residual_rms(machine, setup, measurements, method: str) -> tuple[dict[str, float], int]:
    """RMS per unit of the raw residual rows of ``machine`` and ``setup``'s sensor as they are,
    over the poses whose pose could be solved; and how many those were."""
    from pkmcal.identification.engine import measurement_arrays
    from pkmcal.identification.residuals import Model, make_method

    q, y, cmd = measurement_arrays(measurements)
    meth = make_method(method, Model(machine, setup.sensor, setup.noise, q, y, cmd), weighted=False)
    meth.sensor_columns = False
    ev = meth.evaluate(np.concatenate([machine.params, setup.sensor.params]), jac=False, cov=False)
    ok = ev.converged & np.all(np.isfinite(ev.r), axis=1)
    if not ok.any():
        raise PkmcalError(f"machine '{machine.name}' solves none of the {len(ok)} poses of the measurements")
    r = ev.r[ok]
    units = meth.row_units()
    out = {}
    for unit, shown, scale in (("mm", "mm", 1.0), ("rad", "deg", float(np.rad2deg(1.0))), ("1", "1", 1.0)):
        cols = [k for k, u in enumerate(units) if u == unit]
        if cols:
            out[shown] = float(np.sqrt(np.mean(r[:, cols] ** 2))) * scale
    return out, int(ok.sum())


def _with_sensor_fitted(machine, setup, measurements, method: str, priors):
    """``setup`` with the sensor parameters it frees fitted to ``measurements`` for
    ``machine`` held (unchanged when it frees none)."""
    from pkmcal.identification.engine import identify

    if not setup.sensor.default_free:
        return setup
    mine = tuple(p for p in priors if any(fnmatchcase(n, p.pattern) for n in setup.sensor.param_names))
    fit = identify(machine, setup, measurements, method=method, free=list(setup.sensor.default_free), fix="auto",
                   priors=mine)
    return dataclasses.replace(setup, sensor=fit.sensor)


def refit_free(machine, setup, priors=()) -> tuple[str, ...]:
    """The firmware's numbers (besides the common radius) the refit frees: those the
    calibration freed (its record's ``free`` and ``gauge``), so that a parameter the
    calibration held (a delta's arms from Z-probe heights) stays at its value; without that
    record, the firmware's numbers but those the sensor cannot see without a prior on them
    (:func:`pkmcal.identification.residuals.sensor_held_parameters`)."""
    from pkmcal.identification.residuals import sensor_held_parameters

    record = (machine.metadata or {}).get("calibration") or {}
    if "free" in record:
        chosen = set(record.get("free") or ()) | set(record.get("gauge") or ())
        return tuple(n for n in FIRMWARE_FREE if n in chosen)
    held = set(sensor_held_parameters(machine, setup.sensor, priors))
    return tuple(n for n in FIRMWARE_FREE if n not in held)


def machine_covariance(result) -> np.ndarray:
    """The (p, p) covariance of ``result``'s machine parameters (zero for the held ones)."""
    names = list(result.mechanism.param_names)
    cov = np.zeros((len(names), len(names)))
    k = [i for i, n in enumerate(result.free) if n in names]
    idx = [names.index(result.free[i]) for i in k]
    cov[np.ix_(idx, idx)] = np.asarray(result.covariance)[np.ix_(k, k)]
    return cov


def firmware_refit(machine, setup, measurements, heldout=None, *, method: str | None = None,
                   priors=None, free: tuple[str, ...] | None = None) -> FirmwareRefit:
    """Refit the linear delta ``machine`` (a calibrated one) with only its firmware's numbers
    free, and score the full model, the firmware's numbers without a refit and the refit on
    ``measurements`` (and ``heldout``) (module docstring).

    ``method`` default: the calibration record's, else the engine's default; ``priors``
    default: the calibration record's (:func:`recorded_priors`); priors on parameters the
    firmware cannot hold are left out (they are held at 0), and so are the setup's own.
    The firmware's numbers the calibration held stay held (:func:`refit_free`; ``free``, a
    subset of :data:`FIRMWARE_FREE`, names them instead); a refit
    with no residual left over for its free numbers (the common radius among them) is an
    error: it would reproduce the measurements exactly and nothing would check it."""
    from scipy.optimize import minimize_scalar

    from pkmcal.identification.engine import identify
    from pkmcal.identification.priors import Prior
    from pkmcal.identification.residuals import default_method

    if machine.kind != "linear-delta":
        raise PkmcalError(f"the firmware-limited refit is for linear deltas; machine '{machine.name}' is a "
                          f"{machine.kind or 'machine of another kind'}")
    record = (machine.metadata or {}).get("calibration") or {}
    if method is None:
        method = record.get("method") or default_method(setup, machine)
    notes = []
    if priors is None and not record:
        notes.append("the machine file has no calibration record: the refit uses no priors")
    priors = recorded_priors(machine) if priors is None else tuple(priors)

    def matches(p: Prior, names) -> list[str]:
        return [n for n in names if fnmatchcase(n, p.pattern)]

    held_priors = [p for p in priors if matches(p, HELD)]
    if held_priors:
        notes.append("priors on parameters the firmware holds at 0 are left out: "
                     + ", ".join(p.text() for p in held_priors))
    firmware_free = refit_free(machine, setup, priors) if free is None else tuple(free)
    if unknown := [n for n in firmware_free if n not in FIRMWARE_FREE]:
        raise PkmcalError(f"the firmware-limited refit frees only the firmware's numbers ({', '.join(FIRMWARE_FREE)}) "
                          f"and the common radius; not {', '.join(unknown)}")
    fit_priors = tuple(dataclasses.replace(p, origin="calibration record") for p in priors
                       if matches(p, firmware_free) or matches(p, setup.sensor.param_names))
    radius_priors = [(p, n) for p in priors for n in matches(p, RADII)]
    bare = dataclasses.replace(setup, priors=())
    free = list(firmware_free) + [n for n in setup.sensor.default_free]
    start = dropped_machine(machine)
    r0 = float(start.params[PARAM_NAMES.index("radius_a")])
    idx = [PARAM_NAMES.index(n) for n in RADII]
    fits: dict[float, object] = {}

    def fit_at(R: float):
        R = float(R)
        if R not in fits:
            rho = start.params.copy()
            rho[idx] = R
            fits[R] = identify(start.with_params(rho), bare, measurements, method=method, free=free, fix="auto",
                               priors=fit_priors)
        return fits[R]

    def cost(R: float) -> float:
        c = 2.0 * fit_at(R).cost
        for p, n in radius_priors:
            mean = machine.params[PARAM_NAMES.index(n)] if p.mean is None else p.mean
            c += ((R - mean) / p.std) ** 2
        return c

    # the fit's scale: a bracket of ±0.1 % of the radius; Brent's absolute tolerance 1e-7 mm
    opt = minimize_scalar(cost, bracket=(r0 - 1e-3 * r0, r0 + 1e-3 * r0), method="brent",
                          options={"xtol": 1e-7 / r0})
    best = fit_at(opt.x)
    if not best.success:
        raise PkmcalError(f"the firmware-limited refit did not converge ({best.message})")
    dof = int(best.uncertainty.dof) - 1          # the common radius is a free number too
    if dof <= 0:
        raise PkmcalError(f"the firmware-limited refit has {len(best.free) + 1} free numbers (one common radius, "
                          f"{', '.join(best.free)}) for {len(best.free) + 1 + dof} residuals of {len(best.used_poses)} "
                          "poses: it would fit them exactly and nothing would check it; measure more points (Klipper's "
                          "7 are too few for a refit), or export the calibration as it is with --no-refit")
    if held_firmware := [n for n in FIRMWARE_FREE if n not in firmware_free]:
        notes.append(f"held as the calibration held them: {', '.join(held_firmware)}")
    refit_machine = best.mechanism.with_params(best.mechanism.params, name=machine.name)
    refit_setup = dataclasses.replace(bare, sensor=best.sensor)

    def score(label, mech, fitted_setup) -> Score:
        rms, n = residual_rms(mech, fitted_setup, measurements, method)
        h_rms = h_n = None
        if heldout is not None:
            h_rms, h_n = residual_rms(mech, fitted_setup, heldout, method)
        return Score(label, mech, fitted_setup.sensor, rms, n, h_rms, h_n)

    dropped = dropped_machine(machine)
    scores = (score("full model (every parameter)", machine,
                    _with_sensor_fitted(machine, bare, measurements, method, fit_priors)),
              score("firmware numbers, not refitted", dropped,
                    _with_sensor_fitted(dropped, bare, measurements, method, fit_priors)),
              score("firmware-limited refit (exported)", refit_machine, refit_setup))
    return FirmwareRefit(*scores, free=tuple(n for n in best.free), gauge=tuple(best.gauge),
                         priors=tuple(p.text() for p in priors if p not in held_priors), method=method,
                         notes=tuple(notes), covariance=machine_covariance(best))


__all__ = [
    "FIRMWARE_FREE",
    "HELD",
    "RADII",
    "FirmwareRefit",
    "Score",
    "dropped_machine",
    "firmware_refit",
    "machine_covariance",
    "recorded_priors",
    "refit_free",
    "residual_rms",
]
