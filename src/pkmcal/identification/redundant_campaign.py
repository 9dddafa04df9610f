"""Simulated campaigns and held-out verification of redundantly actuated machines (paper 3 §2–3).

A redundant machine (l actuators > n pose coordinates) commanded with readings c is
over-constrained: the real machine does not go to FK(c) but settles where its actuator
springs and the tool load balance (:func:`pkmcal.mechanisms.statics.equilibrium`,
paper 3 eq. 1–3 solved nonlinearly)

    Γᵀ K (q(x) − c) − J_fᵀ F = 0,   c = IK(x_c, ρ_nom),

with K and F from the setup's ``simulation:`` block (:class:`~pkmcal.mechanisms.statics.StaticsModel`),
never seen by the identifier (nor the block's backlash, which shifts each actuator by half
its dead band against the direction of its last commanded motion, poses taken in the
order given). The encoders then read q(x) + e_q (following error
q(x) − c ≠ 0) and the tracker y = h(x, θ) + e_y, with the setup's noise.

Verification (paper 3 §3, Fig. 5/8): the tracker reading each held-out commanded pose x_c
should give is y* = h(x_c, θ_setup). A model (mechanism M, sensor S_M) commands it as
c = IK(S_M⁻¹(y*), ρ_M) (:func:`commands_for_targets`; for n = 3 at the commanded plate
angle); the real machine settles under the setup's stiffness and load, and the tool error
is e = ‖h(x_eq, θ_setup) − y*‖ (mm). "Before" is the nominal machine with the setup's
sensor, "after" the calibrated machine with the sensor parameters identified with it
(stored in its file's ``calibration.sensor`` block).

Baselines of paper 3 §1 (:func:`baseline_inputs`), fitted by the engine's ``projection``
method: ``ignore-redundancy`` (actuators assumed at their commands) and
``actuator-subset`` (n of the l actuators, a non-redundant calibration).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import (
    SimulationResult,
    campaign_inputs,
    drop_limit_violations,
    perturb_machine,
)
from pkmcal.identification.uncertainty import embed
from pkmcal.identification.verification import error_stats
from pkmcal.io.tables import to_file_units
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.statics import StaticsModel, equilibrium
from pkmcal.sensors.base import MeasurementSetup


def is_redundant(machine: Mechanism) -> bool:
    """True for a redundantly actuated machine (more actuators than pose coordinates)."""
    return machine.n_actuators > machine.n_dof


def _statics(setup: MeasurementSetup, machine: Mechanism) -> tuple[np.ndarray, np.ndarray | None]:
    sim: StaticsModel | None = setup.simulation
    if sim is None:
        raise PkmcalError(f"machine '{machine.name}' is redundantly actuated: simulating it needs the actuator "
                          "stiffness (and the tool load) in the setup's 'simulation:' block, e.g. "
                          "simulation: {stiffness: 2.0e4, load: [0, -30]} (N/mm or N*mm/rad; N)")
    return sim.stiffness_for(machine), sim.load


def commands_for_targets(mechanism: Mechanism, sensor, targets: np.ndarray, angles=None,
                         statics: StaticsModel | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Poses (N, n) and commanded readings (N, l) that put the tool on ``targets`` (N, 2,
    tracker frame) according to the model: x = S⁻¹(y*) (``sensor.poses_for_readings``, for
    n = 3 at the plate ``angles``), c = IK(x, ρ). With ``statics`` (a model that knows the
    stiffness K and load F, paper 3 ref. [7]) the commands are pre-deflected so that the
    model's equilibrium is x: c = IK(x) − Γ (ΓᵀKΓ)⁻¹ J_fᵀ F at x, which satisfies
    Γᵀ K (IK(x) − c) = J_fᵀ F exactly (:mod:`pkmcal.mechanisms.statics`)."""
    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    ang = np.array(mechanism.pose_is_angle, dtype=bool)
    ref = np.tile(mechanism.home_pose, (targets.shape[0], 1))    # the plate rotation at the angles
    if angles is not None:
        ref[:, ang] = np.reshape(angles, (targets.shape[0], -1))
    poses = mechanism.poses_from_frame(sensor.frame_for_readings(targets, mechanism.frame(ref).R))
    poses[:, ang] = ref[:, ang]                                     # the given angles, exactly
    c = mechanism.ik(poses)
    if statics is not None and statics.load is not None:
        K = statics.stiffness_for(mechanism)
        G = mechanism.actuator_pose_jacobian(poses)
        Jf = mechanism.pose_jacobian_from_twist(sensor.tool_frame_jacobian(mechanism.frame(poses)), poses)
        b = np.einsum("nki,k->ni", Jf, statics.load)
        dx = np.linalg.solve(np.einsum("nli,l,nlj->nij", G, K, G), b[..., None])
        c = c - (G @ dx)[..., 0]
    return poses, c


def _settle(real, setup, commands, guess, ignore_limits):
    """Equilibrium of ``real`` under ``commands`` (N, l), in path order: (poses, readings, ok,
    reasons). With backlash (``simulation.backlash``) the springs act on the commands less
    the backlash shift s b/2 and the encoders read the joints plus it
    (:meth:`~pkmcal.mechanisms.statics.StaticsModel.backlash_shift`)."""
    K, F = _statics(setup, real)
    shift = setup.simulation.backlash_shift(commands)
    n = len(commands)
    finite = np.all(np.isfinite(commands), axis=1) & np.all(np.isfinite(guess), axis=1)
    reasons: dict[int, str] = {int(k): "nominal-ik-failed" for k in np.flatnonzero(~finite)}
    poses = np.array(guess, dtype=float)
    readings = np.full((n, real.n_actuators), np.nan)
    ok = finite.copy()
    if finite.any():
        eq = equilibrium(real, commands[finite] - shift[finite], K, F, setup.sensor, guess=guess[finite])
        idx = np.flatnonzero(finite)
        poses[idx] = eq.poses
        readings[idx] = eq.readings + shift[finite]
        for j in np.flatnonzero(~eq.converged):
            reasons[int(idx[j])] = f"equilibrium-not-converged (force residual {eq.force_residual[j]:.3g})"
        ok[idx[~eq.converged]] = False
    with np.errstate(invalid="ignore"):
        ok = drop_limit_violations(real, np.where(ok[:, None], poses, real.home_pose), ok, ignore_limits, reasons)
    return poses, readings, ok, dict(sorted(reasons.items()))


def simulate_redundant_campaign(
    nominal: Mechanism,
    real: Mechanism,
    setup: MeasurementSetup,
    commanded_poses: np.ndarray,
    rng: np.random.Generator | int | None = None,
    ignore_limits: tuple[str, ...] = (),
) -> SimulationResult:
    """Measure ``commanded_poses`` (N, n; mm, rad) on the redundant ``real`` machine commanded
    with ``nominal``'s IK (module docstring). ``actuator_true`` are the noise-free encoder
    readings at equilibrium (commands + following errors), ``real_poses`` the rest poses.
    Noise is drawn for all N poses before any is dropped (same seed, same bytes)."""
    commanded, e_y, e_q = campaign_inputs(nominal, real, setup, commanded_poses, rng)
    sensor = setup.sensor
    with np.errstate(invalid="ignore"):
        commands = nominal.ik(commanded)
    poses, readings, ok, dropped = _settle(real, setup, commands, commanded, ignore_limits)
    kept = np.flatnonzero(ok)
    q_true = readings[kept]
    y_true = sensor.predict(real.frame(poses[kept])) if len(kept) else np.zeros((0, sensor.n_readings))
    return SimulationResult(commanded=commanded, kept=kept, dropped=dropped, real_poses=poses[kept],
                            actuator_true=q_true, sensor_true=y_true, actuator_readings=q_true + e_q[kept],
                            sensor_readings=y_true + e_y[kept], setup=setup)


def perturb_planar(machine, magnitude_mm: float, rng, distribution: str = "uniform", name: str | None = None,
                   radius_mm: float = 1000.0):
    """:func:`~pkmcal.identification.simulation.perturb_machine` (its angle rule was this
    function's; kept under this name for callers of the planar campaigns)."""
    return perturb_machine(machine, magnitude_mm, rng, distribution, name, radius_mm)


def calibrated_sensor(machine: Mechanism, sensor):
    """``sensor`` with the parameters identified together with ``machine`` (its file's
    ``calibration.sensor`` block: names → values in file units, mm and degrees for the
    parameters the sensor declares angles, ``sensor.param_is_angle``), or ``sensor`` itself
    when the machine has none."""
    cal = (getattr(machine, "metadata", {}) or {}).get("calibration") or {}
    values = cal.get("sensor") if isinstance(cal, dict) else None
    if not values:
        return sensor
    from pkmcal.identification.heldout import sensor_from_values

    return sensor_from_values(sensor, {k: float(v) for k, v in values.items()},
                              f"machine '{machine.name}': calibration.sensor")


def sensor_calibration_block(sensor) -> dict:
    """The ``calibration.sensor`` block (file units: mm, degrees for the parameters of
    ``sensor.param_is_angle``) of an identified sensor; :func:`calibrated_sensor` reads it."""
    values = to_file_units(sensor.params, sensor.param_is_angle)
    return {k: float(v) for k, v in zip(sensor.param_names, values)}


@dataclass(frozen=True)
class ToolErrors:
    """Per held-out pose: tool-point error (mm), plate-angle error (rad; NaN for n = 2),
    ``valid`` where the real machine settled within its limits (``dropped`` the others)."""

    model: str
    tool: np.ndarray
    angle: np.ndarray
    valid: np.ndarray
    dropped: dict[int, str] = field(default_factory=dict)

    def summary(self, mask: np.ndarray) -> dict:
        out: dict = {"poses": int(np.count_nonzero(mask))}
        out.update(error_stats(self.tool[mask], "tool", "mm"))
        if not np.all(np.isnan(self.angle)):
            out.update(error_stats(np.rad2deg(self.angle[mask]), "angle", "deg"))
        return out


def tool_errors(model: Mechanism, model_sensor, real: Mechanism, setup: MeasurementSetup, poses: np.ndarray,
                name: str = "model", ignore_limits: tuple[str, ...] = (), target_sensor=None,
                model_statics: StaticsModel | None = None) -> ToolErrors:
    """Tool errors of ``real`` commanded through (``model``, ``model_sensor``) at the
    held-out ``poses`` (module docstring). The targets are y* = h(x_c) of ``target_sensor``
    (default the setup's): a simulated experiment whose true tool point (the setup's sensor)
    differs from the nominal one passes the nominal sensor, so that "before" includes the
    tool-point error, as on a real machine whose tool point is only known nominally.
    ``model_statics``: the model also knows stiffness and load and pre-deflects its
    commands (:func:`commands_for_targets`)."""
    x_c = model.as_pose_array(poses)
    targets = (setup.sensor if target_sensor is None else target_sensor).predict(model.frame(x_c))
    angles = x_c[:, 2] if model.n_dof == 3 else None
    with np.errstate(invalid="ignore"):
        x_m, commands = commands_for_targets(model, model_sensor, targets, angles, model_statics)
    x_eq, _, ok, dropped = _settle(real, setup, commands, x_m, ignore_limits)
    y = setup.sensor.predict(real.frame(x_eq))
    tool = np.where(ok, np.linalg.norm(y - targets, axis=1), np.nan)
    angle = np.where(ok, x_eq[:, 2] - x_c[:, 2], np.nan) if model.n_dof == 3 else np.full(len(x_c), np.nan)
    return ToolErrors(model=name, tool=tool, angle=angle, valid=ok, dropped=dropped)


@dataclass(frozen=True)
class RedundantVerification:
    """Held-out tool errors of the calibrated machine ("after") and of the nominal one
    ("before", when given); summaries over the poses both reach."""

    after: ToolErrors
    before: ToolErrors | None = None

    @property
    def common(self) -> np.ndarray:
        return self.after.valid if self.before is None else self.after.valid & self.before.valid

    @property
    def dropped(self) -> dict[int, str]:
        """{pose index: why it is not compared}, naming the model whose commands the real
        machine could not follow when there is a 'before' model (a pose left out by either
        is left out of both)."""
        if self.before is None:
            return dict(self.after.dropped)
        return {k: "; ".join(f"{label} model: {d[k]}" for label, d in (("nominal", self.before.dropped),
                                                                         ("calibrated", self.after.dropped)) if k in d)
                for k in sorted(set(self.before.dropped) | set(self.after.dropped))}

    def to_dict(self) -> dict:
        n = len(self.after.valid)
        out = {"after": self.after.summary(self.common),
               "dropped": {str(k + 1): v for k, v in self.dropped.items()},
               "compared_set": (f"the {int(self.common.sum())} of {n} held-out poses at which the real machine settles "
                                "within its limits when commanded through "
                                + ("both models (the same poses before and after)" if self.before is not None
                                   else "the calibrated model"))}
        if self.before is not None:
            out["before"] = self.before.summary(self.common)
            b, a = out["before"]["tool_mean_mm"], out["after"]["tool_mean_mm"]
            out["improvement_pct"] = float(100.0 * (1.0 - a / b)) if b > 0 else float("nan")
        out["units"] = {"poses": "1", "dropped": "keys: held-out pose numbers = data rows of the pose file, 1-based"}
        return out

    def format_table(self) -> str:
        d = self.to_dict()
        cols = [k for k in ("before", "after") if k in d]
        keys = [k for k in d["after"] if k != "poses"]
        rows = [("measure",) + tuple(cols)] + [(k,) + tuple(f"{d[c][k]:.6g}" for c in cols) for k in keys]
        w = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines = [f"{d['after']['poses']} held-out poses (tool error = |tracker reading - target|; real machine at "
                 "equilibrium under the setup's stiffness and load)", f"compared: {d['compared_set']}"]
        lines += ["  ".join(f"{c:<{w[i]}}" if i == 0 else f"{c:>{w[i]}}" for i, c in enumerate(r)) for r in rows]
        if "improvement_pct" in d:
            lines.append(f"improvement of the mean tool error: {d['improvement_pct']:.1f} %")
        for k, v in d["dropped"].items():
            lines.append(f"pose {k} not reached: {v}")
        if d["dropped"]:
            lines.append("(pose numbers: data rows of the held-out pose file, 1-based)")
        return "\n".join(lines)


def verify_redundant(calibrated: Mechanism, real: Mechanism, setup: MeasurementSetup, poses: np.ndarray,
                     nominal: Mechanism | None = None, ignore_limits: tuple[str, ...] = ()) -> RedundantVerification:
    """Held-out verification of a calibrated redundant machine (module docstring)."""
    for m in (calibrated, nominal):
        if m is not None and (m.n_dof != real.n_dof or m.n_actuators != real.n_actuators):
            raise PkmcalError(f"machine '{m.name}' and the real machine '{real.name}' are not the same kind")
    after = tool_errors(calibrated, calibrated_sensor(calibrated, setup.sensor), real, setup, poses, "after",
                        ignore_limits)
    before = None
    if nominal is not None:
        before = tool_errors(nominal, setup.sensor, real, setup, poses, "before", ignore_limits)
    report = RedundantVerification(after=after, before=before)
    if not report.common.any():
        raise PkmcalError(f"the real machine '{real.name}' settles within its limits at none of the {len(after.valid)} "
                          f"held-out poses ({'; '.join(sorted(set(report.dropped.values())))}); choose poses inside "
                          "its workspace")
    return report


# -- baselines of paper 3 §1 through the engine ------------------------------------------

#: Identification baselines for redundant machines (``pkmcal identify --method``).
BASELINES = ("ignore-redundancy", "actuator-subset")


def baseline_inputs(method: str, nominal: Mechanism, setup: MeasurementSetup, meas, keep=None):
    """``(machine, setup, measurements)`` that turn the engine's ``projection`` fit into the
    baseline ``method`` (paper 3 §1):

    * ``ignore-redundancy``: the encoder readings replaced by the commands IK(x_c, ρ_nom)
      of the commanded poses (following errors ignored; needs the cmd_ columns);
    * ``actuator-subset``: only the actuators ``keep`` (0-based; default the first n) are
      used (:class:`~pkmcal.identification.projection.ActuatorSubset`), a non-redundant fit.
    """
    from pkmcal.identification.projection import ActuatorSubset  # projection imports this module

    if method not in BASELINES:
        raise PkmcalError(f"unknown baseline '{method}'; use one of {', '.join(BASELINES)}")
    if not is_redundant(nominal):
        raise PkmcalError(f"--method {method} is a baseline for redundantly actuated machines; machine "
                          f"'{nominal.name}' has {nominal.n_actuators} actuators for {nominal.n_dof} pose coordinates")
    if method == "ignore-redundancy":
        if meas.commanded is None:
            raise PkmcalError("--method ignore-redundancy replaces the encoder readings by the commands, which come "
                              "from the commanded poses: the measurement file needs the cmd_ columns")
        with np.errstate(invalid="ignore"):
            commands = nominal.ik(meas.commanded)
        return nominal, setup, dataclasses.replace(meas, actuators=commands)
    keep = tuple(range(nominal.n_dof)) if keep is None else tuple(int(k) for k in keep)
    if len(keep) != nominal.n_dof or len(set(keep)) != len(keep) or not all(0 <= k < nominal.n_actuators for k in keep):
        raise PkmcalError(f"--keep: give {nominal.n_dof} different actuator numbers of 1..{nominal.n_actuators} "
                          f"(e.g. {','.join(str(i + 1) for i in range(nominal.n_dof))}); got "
                          f"{','.join(str(k + 1) for k in keep)}")
    sub = ActuatorSubset(nominal, keep)
    return (sub, dataclasses.replace(setup, noise=sub.noise(setup.noise)),
            dataclasses.replace(meas, actuators=np.asarray(meas.actuators)[:, list(keep)]))


def baseline_result(result, nominal: Mechanism, method: str):
    """The engine's result of a baseline fit as a result of ``nominal``'s kind (covariance
    kept; ``method`` named)."""
    mech = result.mechanism
    base = getattr(mech, "base", None)
    if base is not None:
        names = tuple(nominal.param_names)
        sel = [i for i, n in enumerate(result.free) if n in names]
        idx = np.array([names.index(result.free[i]) for i in sel], dtype=int)
        cov = embed(np.asarray(result.covariance)[np.ix_(sel, sel)], idx, len(names)) if sel else None
        mech = base.with_params(base.params, covariance=cov)
    return dataclasses.replace(result, mechanism=mech, method=method)


# -- what the following errors say about the load deflection ------------------------------


def load_deflection_estimate(mechanism: Mechanism, sensor, poses: np.ndarray, following_errors: np.ndarray) -> np.ndarray:
    """Tool deflection (N, 2) (mm) implied by the measured following errors e_j = q̂_j − c_j at
    the rest poses ``poses`` (N, n): d_j = J_f (ΓᵀΓ)⁻¹ Γᵀ e_j.

    At equilibrium Γᵀ K e = J_fᵀ F (:mod:`pkmcal.mechanisms.statics`). With equal actuator
    stiffness K = k I the part of e along Γ is then exactly the linear load deflection
    dx = (ΓᵀKΓ)⁻¹ J_fᵀ F, whatever the actuators' conflict (which lies in the null space of
    Γᵀ); with unequal stiffness it is an estimate whose error is the conflict's leak into the
    range of Γ. No stiffness is needed: the data say how far the machine gave way."""
    x = mechanism.as_pose_array(poses)
    G = mechanism.actuator_pose_jacobian(x)
    e = np.asarray(following_errors, dtype=float)
    dx = np.linalg.solve(np.swapaxes(G, 1, 2) @ G, np.einsum("nli,nl->ni", G, e)[..., None])[..., 0]
    Jf = mechanism.pose_jacobian_from_twist(sensor.tool_frame_jacobian(mechanism.frame(x)), x)
    return np.einsum("nki,ni->nk", Jf, dx)


def compliance_warning(nominal: Mechanism, calibrated: Mechanism, sensor, commanded: np.ndarray, rest_poses: np.ndarray,
                       tracker_std: float) -> str | None:
    """A warning when a redundant machine visibly deflected under its load during calibration
    (:func:`load_deflection_estimate` at the rest poses of a projection fit, following
    errors IK(x*, ρ̂) − IK(x_c, ρ_nom)); None when the largest deflection is below twice the
    tracker noise."""
    with np.errstate(invalid="ignore"):
        e = calibrated.ik(rest_poses) - nominal.ik(commanded)
    d = np.linalg.norm(load_deflection_estimate(calibrated, sensor, rest_poses, e), axis=1)
    if not np.any(np.isfinite(d)) or np.nanmax(d) <= 2.0 * tracker_std:
        return None
    return (f"the machine deflected under its load by up to {np.nanmax(d):.3g} mm (mean {np.nanmean(d):.3g} mm) "
            "during calibration, as its following errors show (their part along the pose Jacobian, exact for "
            "equal actuator stiffness); no kinematic calibration removes that deflection: the projection model "
            "keeps it at this load, a fit that ignores the redundancy absorbs it into the parameters and looks "
            "better at this load only (docs/redundant-machines.md, load and compliance)")
