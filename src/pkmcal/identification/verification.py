"""Verification of a calibration on held-out poses: how far the real machine lands from
where it is commanded, with the nominal model ("before") and the calibrated one ("after").

For a model M (nominal or calibrated) and a commanded pose x_c, the actuators are commanded
with q = IK(x_c, ρ_M) and the real machine reaches x_r = FK(q, ρ_real) (Newton from x_c).
Paper 1 §IV reports the pose errors; paper 2 §5 (Table 5) the errors its indicators see:

    position error     e_p = ‖p_r − p_c‖ (mm)
    orientation error  e_R = ∠(R_r R_cᵀ) (rad, :func:`pkmcal.conventions.rotation_error`)
    plane tilt         e_n = ∠(n_r, n_c), n = R e_z (rad): the tilt the indicators see
    height error       e_z = z of the real platform plane (through p_r, normal n_r) above the
                       commanded centre (x_c, y_c), minus z_c (mm): the height an indicator
                       under the platform centre sees (eq. 6 with d_off = 0)

Summaries (mean, max, RMS; for e_z of |e_z|) are taken over the poses that both models
bring the real machine to, so that "before" and "after" compare the same poses; a pose the
real machine cannot reach through either model (FK not converged or on another assembly
mode, real limits) is reported with the model that failed. Angles in degrees in the
summaries (``*_deg``; ``*_rad`` are deprecated aliases).

What is compared (``compare``, :data:`COMPARES`; issue 11 item 4). A calibration that also
estimated the sensor's frames (a laser tracker with a free tracker frame) fixes a gauge: its
base and platform frames are a choice, and platform poses "as commanded" compare frames the
gauge made arbitrary (a correct calibration then looks like a large degradation).

* ``commanded``: the errors above, each model in its own frames (the papers' figures);
* ``aligned``: the same errors after the best rigid alignment T_r ≈ A·T_c·B of base and
  platform frames per model (:mod:`pkmcal.identification.alignment`);
* ``sensor``: what the true instrument reads at the real pose, h_true(F_real(x_r)), against
  what the model predicts its registered instrument reads at the commanded pose,
  h_M(F_M(x_c)) (tool point/frame in the world frame; errors as in
  :mod:`pkmcal.identification.heldout`).

With ``aligned`` and ``sensor`` the poses, given in the nominal machine's frames, are first
carried into the calibrated model's frames (:func:`~pkmcal.identification.alignment.transport_poses`),
so that both models command the same physical poses whatever the gauge.

* ``tool``: a machine that settles at static equilibrium (redundantly actuated, paper 3 §3:
  :func:`~pkmcal.identification.simulation.settles_at_equilibrium`) is commanded to put its
  tool on the tracker reading of each held-out pose and compared on what the tracker reads
  (:mod:`pkmcal.identification.tool_errors`); it needs the setup's stiffness and load.

The errors are those of the platform frames (p, R) of the reached and the commanded pose
coordinates (``Mechanism.frame``), so that every mechanism is verified the same way (a
hexapod's frame is its pose x, y, z, a, b, c; a delta's R = I, no orientation rows).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pkmcal.conventions import rotation_error
from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import drop_limit_violations, settles_at_equilibrium
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors.base import MeasurementSetup

#: Error measures: key → (unit, description).
MEASURES = {
    "position": ("mm", "position error"),
    "orientation": ("rad", "orientation error"),
    "tilt": ("rad", "plane tilt error"),
    "height": ("mm", "height error at centre (z)"),
}


@dataclass(frozen=True)
class PoseErrors:
    """Per-pose errors (N,) of one model (see module docstring); ``valid`` (N,) False where
    the real machine cannot reach the pose (errors NaN there), with the reason in
    ``dropped``; ``reached`` (N, 6) the real machine's poses (mm, rad)."""

    model: str
    reached: np.ndarray
    position: np.ndarray | None
    orientation: np.ndarray | None
    tilt: np.ndarray | None
    height: np.ndarray | None
    valid: np.ndarray
    dropped: dict[int, str] = field(default_factory=dict)
    #: (N, m) reading residuals (true instrument − model's prediction) of a sensor that
    #: reads neither a position nor an orientation (indicators; compare="sensor" only)
    reading: np.ndarray | None = None
    #: (N, n) the poses commanded, in the frames the errors compare them in (after the
    #: alignment with compare="aligned"), for the ISO 9283 figures (:mod:`.iso9283`)
    commanded: np.ndarray | None = None

    def summary(self, mask: np.ndarray | None = None) -> dict[str, float]:
        """``{position_mean_mm, position_max_mm, position_rms_mm, orientation_mean_deg, …}``
        over ``mask`` (default: the valid poses); signed height errors are taken as |e_z|.
        Angles in degrees (``*_deg``); the ``*_rad`` keys are the same values in radians,
        kept as deprecated aliases for scripts that read them."""
        m = self.valid if mask is None else mask
        out: dict[str, float] = {"poses": int(np.count_nonzero(m))}
        for key, (unit, _) in MEASURES.items():
            values = getattr(self, key)
            if values is None:   # not seen by the sensor compared (compare="sensor")
                continue
            out.update(error_stats(values[m], key, unit))
            if unit == "rad":
                out.update(error_stats(np.rad2deg(values[m]), key, "deg"))
        if self.reading is not None:
            out.update(error_stats(self.reading[m].reshape(-1), "reading", "mm"))
        return out


def error_stats(values: np.ndarray, key: str, unit: str) -> dict[str, float]:
    """``{key_mean_unit, key_max_unit, key_rms_unit}`` of |values| (NaN when empty)."""
    v = np.abs(values)
    stats = (float(np.mean(v)), float(np.max(v)), float(np.sqrt(np.mean(v**2)))) if v.size else (float("nan"),) * 3
    return {f"{key}_{name}_{unit}": x for name, x in zip(("mean", "max", "rms"), stats)}


def frame_errors(p_r: np.ndarray, R_r: np.ndarray, p_c: np.ndarray, R_c: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(e_p, e_R, e_n, e_z)`` (N,) of reached frames (p_r, R_r) against commanded ones
    (p_c, R_c) (module docstring)."""
    e_p = np.linalg.norm(p_r - p_c, axis=1)
    e_R = rotation_error(R_r, R_c)
    nc, nr = R_c[:, :, 2], R_r[:, :, 2]
    cross = np.linalg.norm(np.cross(nr, nc), axis=1)
    e_n = np.arctan2(cross, np.einsum("nk,nk->n", nr, nc))
    # plane through p_r with normal n_r, height above (x_c, y_c): eq. (6) with d_off = 0
    with np.errstate(divide="ignore", invalid="ignore"):
        z_plane = (np.einsum("nk,nk->n", nr, p_r) - nr[:, 0] * p_c[:, 0] - nr[:, 1] * p_c[:, 1]) / nr[:, 2]
    return e_p, e_R, e_n, z_plane - p_c[:, 2]


def pose_errors(model: Mechanism, real: Mechanism, poses: np.ndarray, ignore_limits: tuple[str, ...] = ()) -> PoseErrors:
    """Errors of the real machine commanded through ``model`` at ``poses`` (N, n; mm, rad):
    of the platform frames (position, orientation) of the reached and the commanded poses.

    ``ignore_limits`` names limits of the real machine not checked (e.g. ``leg_collision``).
    """
    return pose_errors_many((model,), real, poses, ignore_limits)[0]


def pose_errors_many(models: tuple[Mechanism, ...] | list[Mechanism], real: Mechanism, poses: np.ndarray,
                     ignore_limits: tuple[str, ...] = ()) -> tuple[PoseErrors, ...]:
    """:func:`pose_errors` of each of ``models`` at the same ``poses`` on the same ``real``
    machine, with one FK, one limit check and one pass of the error formulas over all
    K·N commanded poses instead of K of each: every step works pose by pose, so each
    result holds the same numbers as its own :func:`pose_errors` call (tested), for a
    fraction of the per-call cost when N is small (a study's held-out poses, checked
    with the nominal model and every calibrated one)."""
    for model in models:
        if model.pose_names != real.pose_names:
            raise PkmcalError(f"machine '{model.name}' has poses ({', '.join(model.pose_names)}) and the real "
                              f"machine '{real.name}' ({', '.join(real.pose_names)}): compare machines of one kind")
    cmd1 = models[0].as_pose_array(poses)
    if not np.all(np.isfinite(cmd1)):
        raise PkmcalError("a held-out pose is not a finite number")
    n, k = len(cmd1), len(models)
    q = np.concatenate([model.ik(cmd1) for model in models]) if k > 1 else models[0].ik(cmd1)
    cmd = np.tile(cmd1, (k, 1)) if k > 1 else cmd1
    finite = np.all(np.isfinite(q), axis=1)
    fk = real.fk(np.where(finite[:, None], q, 0.0), guess=cmd)
    dropped: dict[int, str] = {}
    for i in np.flatnonzero(~finite):
        dropped[int(i)] = "ik-failed"
    for i in np.flatnonzero(finite & ~fk.converged):
        dropped[int(i)] = "fk-not-converged"
    for i in np.flatnonzero(finite & fk.branch_changed):
        dropped[int(i)] = "fk-other-assembly-mode"
    ok = finite & fk.ok
    reached = np.where(ok[:, None], fk.poses, cmd)
    ok = drop_limit_violations(real, reached, ok, ignore_limits, dropped)

    f_c, f_r = models[0].frame(cmd1), real.frame(reached)       # platform frames (p, R) of the poses
    Rc = np.tile(f_c.R, (k, 1, 1)) if k > 1 else f_c.R
    e_p, e_R, e_n, e_z = frame_errors(f_r.p, f_r.R, np.tile(f_c.p, (k, 1)) if k > 1 else f_c.p, Rc)
    nan = np.where(ok, 1.0, np.nan)
    rotates = any(real.pose_is_angle)      # a machine without angle coordinates (a delta) keeps R = I
    out = []
    for j, model in enumerate(models):
        rows = slice(j * n, (j + 1) * n)
        mine = {i - j * n: why for i, why in sorted(dropped.items()) if j * n <= i < (j + 1) * n}
        out.append(PoseErrors(model=model.name, reached=reached[rows], position=(e_p * nan)[rows],
                              orientation=(e_R * nan)[rows] if rotates else None,
                              tilt=(e_n * nan)[rows] if rotates else None, height=(e_z * nan)[rows],
                              valid=ok[rows], dropped=mine, commanded=cmd1))
    return tuple(out)


@dataclass(frozen=True)
class VerificationReport:
    """Before/after errors on held-out poses: :class:`PoseErrors` of each model, or with
    ``compare="tool"`` (a machine at equilibrium) its
    :class:`~pkmcal.identification.tool_errors.ToolErrors`. ``before`` is None without a
    nominal model. Summaries use the poses both models reach (``common``)."""

    real: str
    after: PoseErrors
    before: PoseErrors | None = None
    #: what is compared (:data:`COMPARES`): "commanded", "aligned", "sensor" or "tool"
    compare: str = "commanded"
    #: compare="aligned": the alignment of each model ("before", "after")
    alignment: dict = field(default_factory=dict)
    #: compare="aligned" / "sensor" with a nominal model: the alignment that carried the
    #: held-out poses (nominal frames) into the calibrated model's frames ("after")
    transported: dict = field(default_factory=dict)

    @property
    def common(self) -> np.ndarray:
        m = self.after.valid.copy()
        if self.before is not None:
            m &= self.before.valid
        return m

    @property
    def dropped(self) -> dict[int, str]:
        """{pose index: why it is not compared}; with a 'before' model, each reason names
        the model whose commands the real machine could not follow ("nominal model: …",
        "calibrated model: …"), since a pose left out by either is left out of both."""
        if self.before is None:
            return dict(self.after.dropped)
        out: dict[int, str] = {}
        for k in sorted(set(self.before.dropped) | set(self.after.dropped)):
            parts = [f"{label} model: {d[k]}" for label, d in (("nominal", self.before.dropped),
                                                               ("calibrated", self.after.dropped)) if k in d]
            out[k] = "; ".join(parts)
        return out

    def reached_by(self) -> dict[str, int]:
        """Pose counts: reached through both models, only one of them, neither."""
        a = self.after.valid
        b = self.before.valid if self.before is not None else a
        return {"both": int(np.count_nonzero(a & b)), "calibrated_only": int(np.count_nonzero(a & ~b)),
                "nominal_only": int(np.count_nonzero(~a & b)), "neither": int(np.count_nonzero(~a & ~b))}

    def compared_set(self) -> str:
        """Which poses the figures are taken over, and why that set (one sentence)."""
        n = len(self.after.valid)
        if self.compare == "tool":
            return (f"the {int(self.common.sum())} of {n} held-out poses at which the real machine settles within its "
                    "limits when commanded through " + ("both models (the same poses before and after)"
                                                        if self.before is not None else "the calibrated model"))
        if self.before is None:
            return (f"the {int(self.after.valid.sum())} of {n} held-out poses the real machine reaches when commanded "
                    "through the calibrated model (with a nominal model, only the poses both models bring it to "
                    "are compared, so that before and after are taken over the same poses)")
        r = self.reached_by()
        return (f"the {r['both']} of {n} held-out poses the real machine reaches when commanded through both models, "
                f"the same poses before and after ({r['calibrated_only']} reached through the calibrated model only, "
                f"{r['nominal_only']} through the nominal model only, {r['neither']} through neither: listed below)")

    def to_dict(self) -> dict:
        """JSON-ready: ``{"poses": N, "used": K, "real": …, "after": {...}, "before": {...},
        "dropped": [{"pose": 1-based, "reason": …}], "reduction_percent": {...}}``; units
        in the key names (``_mm``, ``_deg``; ``_rad`` keys are deprecated aliases) and in
        ``units``. With ``compare="tool"``: ``{"after": {poses, tool_*_mm[, angle_*_deg]},
        "dropped": {pose number: reason}, "compared_set", "before", "improvement_pct",
        "units"}`` (the keys of ``verify --json`` for redundant machines since they exist)."""
        if self.compare == "tool":
            return self._tool_dict()
        mask = self.common
        out: dict = {"poses": int(len(mask)), "used": int(np.count_nonzero(mask)), "real": self.real,
                     "calibrated": self.after.model, "compared_set": self.compared_set(),
                     "compare": self.compare, "compared": COMPARES[self.compare]}
        if self.alignment:
            out["alignment"] = {k: a.to_dict() for k, a in self.alignment.items()}
        if self.transported:
            out["poses_transported"] = {
                "note": "the held-out poses are given in the nominal machine's frames; the calibrated model is "
                        "commanded at the same poses expressed in its own frames (T_nominal = A T_calibrated B, "
                        "fitted on both models' FK at the nominal IK of the poses)",
                **{k: (a if isinstance(a, str) else a.to_dict()) for k, a in self.transported.items()}}
        if self.before is not None:
            out["nominal"] = self.before.model
            out["reached_by"] = self.reached_by()
            out["before"] = self.before.summary(mask)
        out["after"] = self.after.summary(mask)
        if self.before is not None:
            b, a = out["before"], out["after"]
            out["reduction_percent"] = {
                k[: -len("_mm") if k.endswith("_mm") else -len("_rad")]: (100.0 * (1.0 - a[k] / b[k]) if b[k] > 0 else None)
                for k in a if k.endswith(("_mm", "_rad")) and "_mean_" in k
            }
        out["dropped"] = [{"pose": k + 1, "reason": why} for k, why in self.dropped.items()]
        out["units"] = {"poses": "1", "used": "1", "reached_by": "1 (pose counts)",
                        "pose": "1: held-out pose number = data row of the pose file, 1-based"}
        out["deprecated"] = "the *_rad keys repeat the *_deg values in radians; read the *_deg keys"
        return out

    def _tool_dict(self) -> dict:
        out = {"after": self.after.summary(self.common),
               "dropped": {str(k + 1): v for k, v in self.dropped.items()},
               "compared_set": self.compared_set()}
        if self.before is not None:
            out["before"] = self.before.summary(self.common)
            b, a = out["before"]["tool_mean_mm"], out["after"]["tool_mean_mm"]
            out["improvement_pct"] = float(100.0 * (1.0 - a / b)) if b > 0 else float("nan")
        out["units"] = {"poses": "1", "dropped": "keys: held-out pose numbers = data rows of the pose file, 1-based"}
        return out

    def _tool_table(self) -> str:
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

    def format_table(self) -> str:
        """A before/after table for the terminal (angles in degrees)."""
        if self.compare == "tool":
            return self._tool_table()
        d = self.to_dict()
        cols = (["before"] if self.before is not None else []) + ["after"]
        lines = [f"verification on {d['used']} of {d['poses']} held-out poses; real machine '{self.real}'",
                 f"compared ({self.compare}): {d['compared']}", f"poses: {d['compared_set']}"]
        head = f"{'error':<36}" + "".join(f"{c:>14}" for c in cols)
        if self.before is not None:
            head += f"{'reduction':>11}"
        lines.append(head)
        for key, (unit, text) in {**MEASURES, "reading": ("mm", "reading residual")}.items():
            show_unit = "deg" if unit == "rad" else unit
            for stat in ("mean", "max", "rms"):
                name = f"{key}_{stat}_{show_unit}"
                if name not in d["after"]:
                    continue
                row = f"{text + ' ' + stat + ' (' + show_unit + ')':<36}"
                row += "".join(f"{d[c][name]:>14.6g}" for c in cols)
                if self.before is not None:
                    b, a = d["before"][name], d["after"][name]
                    row += f"{100 * (1 - a / b):>10.1f}%" if b > 0 else f"{'-':>11}"
                lines.append(row)
        for item in d["dropped"]:
            lines.append(f"  pose {item['pose']} not used: {item['reason']}")
        if d["dropped"]:
            lines.append("  (pose numbers: data rows of the held-out pose file, 1-based)")
        return "\n".join(lines)


#: What :func:`verify` compares, and how the output says it.
COMPARES = {
    "commanded": "the real machine's platform pose against the commanded one, each in its model's frames (depends "
                 "on the gauge when the calibration estimated sensor frames)",
    "aligned": "the real machine's platform frames against the commanded ones after the best rigid alignment "
               "T_real = A T_cmd B of the base (A) and platform (B) frames, fitted per model over the poses "
               "compared (independent of the gauge)",
    "sensor": "what the true instrument reads at the real machine's pose against what the model predicts it reads "
              "at the commanded pose (tool point/frame in the world frame; each model with its own registration "
              "of the instrument; independent of the gauge)",
    "tool": "what the tracker reads at the real machine's rest pose (static equilibrium under the setup's stiffness "
            "and load) against the target reading of each held-out pose, which each model commands",
}


def aligned_errors(pe: PoseErrors, cmd: np.ndarray, mask: np.ndarray, model: Mechanism):
    """``(pe with the errors after the alignment fitted on mask, alignment)``: the errors of
    ``verify(compare="aligned")`` from those as commanded ``cmd`` (frames of ``model``'s
    poses)."""
    from pkmcal.identification.alignment import align_poses

    a = align_poses(pe.reached[mask], cmd[mask], model)
    f_c, f_r = model.frame(cmd), model.frame(pe.reached)
    p_c, R_c = a.apply(f_c.p, f_c.R)
    with np.errstate(invalid="ignore"):
        e_p, e_R, e_n, e_z = frame_errors(f_r.p, f_r.R, p_c, R_c)
    nan = np.where(pe.valid, 1.0, np.nan)
    return replace(pe, position=e_p * nan, orientation=None if pe.orientation is None else e_R * nan,
                   tilt=None if pe.tilt is None else e_n * nan, height=e_z * nan,
                   commanded=model.poses_from_frame(Frame(p_c, R_c))), a


def _sensed(pe: PoseErrors, model: Mechanism, sensor, real: Mechanism, true_sensor, cmd: np.ndarray) -> PoseErrors:
    """``pe`` with the errors of what the instruments read: the true one at the real pose,
    against the model's registered ``sensor`` at the commanded pose."""
    from pkmcal.identification.heldout import reading_errors

    with np.errstate(all="ignore"):
        y_true = true_sensor.predict(real.frame(np.where(pe.valid[:, None], pe.reached, cmd)))
        y_model = sensor.predict(model.frame(cmd))
    r, e_p, e_R = reading_errors(sensor, y_true, y_model, pe.valid)
    return replace(pe, position=e_p, orientation=e_R, tilt=None, height=None,
                   reading=r if e_p is None else None)


def transported(model: Mechanism, poses: np.ndarray, reference: Mechanism | None = None) -> np.ndarray:
    """The held-out ``poses`` as ``model`` commands them: given in ``reference``'s frames
    (the nominal machine), carried into the model's
    (:func:`~pkmcal.identification.alignment.transport_poses`); as they are without one."""
    cmd = model.as_pose_array(poses)
    if reference is None:
        return cmd
    from pkmcal.identification.alignment import transport_poses

    return transport_poses(model, reference, cmd)[0]


def sensor_errors(model: Mechanism, sensor, real: Mechanism, true_sensor, poses: np.ndarray,
                  ignore_limits: tuple[str, ...] = (), reference: Mechanism | None = None) -> PoseErrors:
    """``verify(compare="sensor")`` for one model: the real machine commanded through
    ``model`` to the held-out ``poses``, what ``true_sensor`` reads at the pose it reaches
    against what ``model`` predicts its registered ``sensor`` reads at the commanded one.
    ``reference`` (the nominal machine): the poses are given in its frames and carried into
    the model's first (:func:`~pkmcal.identification.alignment.transport_poses`), so that
    every model commands the same physical poses whatever its gauge."""
    cmd = transported(model, poses, reference)
    return _sensed(pose_errors(model, real, cmd, ignore_limits), model, sensor, real, true_sensor, cmd)


def verify(
    calibrated: Mechanism,
    real: Mechanism,
    poses: np.ndarray,
    nominal: Mechanism | None = None,
    ignore_limits: tuple[str, ...] = (),
    compare: str | None = None,
    sensors: tuple | None = None,
    true_sensor=None,
    frames: Mechanism | None = None,
    setup: MeasurementSetup | None = None,
) -> VerificationReport:
    """Errors of ``real`` commanded through ``calibrated`` (and ``nominal``, "before") at the
    held-out ``poses`` (N, n; mm, rad), for every machine.

    ``compare`` (:data:`COMPARES`; None: ``"tool"`` for a machine that
    :func:`~pkmcal.identification.simulation.settles_at_equilibrium`, which needs the
    ``setup`` with its ``simulation:`` stiffness and load and the calibrated machine's
    identified tracker from its file, else ``"commanded"``): ``"commanded"`` the platform poses as commanded;
    ``"aligned"`` after the best rigid alignment of each model's frames
    (:mod:`pkmcal.identification.alignment`); ``"sensor"`` the readings of ``true_sensor``
    (the real instrument) against those each model predicts with its own sensor,
    ``sensors`` = (calibrated's, nominal's or None). With ``"aligned"`` and ``"sensor"``
    and a nominal model, the poses (in the nominal frames) are carried into the calibrated
    model's frames first (:func:`~pkmcal.identification.alignment.transport_poses`), so
    that both models command the same physical poses whatever the calibration's gauge;
    ``frames`` names the machine whose frames the poses are given in when there is no
    nominal model (the calibration record's nominal machine), None: the calibrated one's."""
    if settles_at_equilibrium(calibrated):
        if compare not in (None, "tool"):
            raise PkmcalError(f"compare='{compare}': machine '{calibrated.name}' settles at static equilibrium; it is "
                              "verified on what its tracker reads (compare='tool')")
        return _verify_tool(calibrated, real, poses, nominal, ignore_limits, setup)
    compare = "commanded" if compare is None else compare
    if compare == "tool":
        raise PkmcalError(f"compare='tool' verifies a machine that settles at static equilibrium; machine "
                          f"'{calibrated.name}' has as many actuators as pose coordinates")
    if compare not in COMPARES:
        raise PkmcalError(f"compare must be one of {', '.join(COMPARES)}; got '{compare}'")
    if compare == "sensor" and (true_sensor is None or sensors is None or sensors[0] is None):
        raise PkmcalError("comparing what the sensor reads needs the true instrument and the calibrated sensor")
    if compare == "sensor" and nominal is not None and sensors[1] is None:
        nominal = None   # no registration of the nominal machine's sensor: no fair 'before'
    cmd = calibrated.as_pose_array(poses)
    transported = {}
    if compare == "commanded":
        if nominal is None:
            after, before = pose_errors(calibrated, real, cmd, ignore_limits), None
        else:
            after, before = pose_errors_many((calibrated, nominal), real, cmd, ignore_limits)
        report = VerificationReport(real=real.name, after=after, before=before, compare=compare)
    else:
        cmd_cal = cmd
        reference = nominal if nominal is not None else frames
        if reference is not None:   # the poses the user means (nominal frames), in the calibration's frames
            from pkmcal.identification.alignment import transport_poses

            cmd_cal, transported["after"] = transport_poses(calibrated, reference, cmd)
            transported["frames_of"] = reference.name
        after = pose_errors(calibrated, real, cmd_cal, ignore_limits)
        before = None if nominal is None else pose_errors(nominal, real, cmd, ignore_limits)
        report = VerificationReport(real=real.name, after=after, before=before, compare=compare)
        mask = report.common
        if mask.any() and compare == "aligned":
            after, a_after = aligned_errors(after, cmd_cal, mask, calibrated)
            alignment = {"after": a_after}
            if before is not None:
                before, alignment["before"] = aligned_errors(before, cmd, mask, nominal)
            report = VerificationReport(real=real.name, after=after, before=before, compare=compare,
                                        alignment=alignment, transported=transported)
        elif mask.any():
            after = _sensed(after, calibrated, sensors[0], real, true_sensor, cmd_cal)
            if before is not None:
                before = _sensed(before, nominal, sensors[1], real, true_sensor, cmd)
            report = VerificationReport(real=real.name, after=after, before=before, compare=compare,
                                        transported=transported)
    if not report.common.any():
        raise PkmcalError(f"the real machine '{real.name}' reaches none of the {len(after.valid)} held-out poses "
                          f"({'; '.join(sorted(set(report.dropped.values())))}); choose poses inside its workspace")
    return report


def _verify_tool(calibrated: Mechanism, real: Mechanism, poses: np.ndarray, nominal: Mechanism | None,
                 ignore_limits: tuple[str, ...], setup: MeasurementSetup | None) -> VerificationReport:
    """``verify(compare="tool")``: the held-out tool errors of a machine at equilibrium
    (:mod:`pkmcal.identification.tool_errors`), "after" with the tracker identified with
    ``calibrated``, "before" with the setup's."""
    from pkmcal.identification.tool_errors import calibrated_sensor, tool_errors

    if setup is None:
        raise PkmcalError(f"machine '{calibrated.name}' is redundantly actuated: verifying it needs the setup with "
                          "the 'simulation:' stiffness and load the real machine settles under")
    for m in (calibrated, nominal):
        if m is not None and m.kind != real.kind:
            raise PkmcalError(f"machine '{m.name}' and the real machine '{real.name}' are not of one kind "
                              f"({m.kind} vs {real.kind})")
    after = tool_errors(calibrated, calibrated_sensor(calibrated, setup.sensor), real, setup, poses, "after",
                        ignore_limits)
    before = None
    if nominal is not None:
        before = tool_errors(nominal, setup.sensor, real, setup, poses, "before", ignore_limits)
    report = VerificationReport(real=real.name, after=after, before=before, compare="tool")
    if not report.common.any():
        raise PkmcalError(f"the real machine '{real.name}' settles within its limits at none of the {len(after.valid)} "
                          f"held-out poses ({'; '.join(sorted(set(report.dropped.values())))}); choose poses inside "
                          "its workspace")
    return report
