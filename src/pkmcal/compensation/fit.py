"""Fitting what a calibrated model leaves, choosing its complexity by cross-validation, and
keeping it only where held-out data show it helps.

**What the model leaves.** For measurement j (actuator readings q_j, sensor readings y_j)
the calibrated machine ρ̂ and identified sensor θ̂ predict x̂_j = FK(q_j, ρ̂) and
ŷ_j = h(x̂_j, θ̂) (the fk-residual of paper 2 §3 eq. 3, :func:`pkmcal.identification.heldout.predict`);
r_j = y_j ⊖ ŷ_j is what the kinematic model cannot explain, plus noise.

**The field.** The real machine is taken to sit at x̂_j + δ(x̂_j), δ a smooth displacement
of the pose (mm, rad), so that to first order

    r_j = H_j δ(x̂_j) + e_j,     H_j = ∂h/∂x at x̂_j  (the sensor's twist Jacobian pulled back
                                   to the pose, :meth:`Mechanism.pose_jacobian_from_twist`),

    Cov e_j = diag(σ_y²) + G_j diag(σ_q²) G_jᵀ,   G_j = H_j (∂q/∂x)⁻¹  (the encoders' noise
                                   carried through FK; square machines).

Two kinds of δ, each linear in its coefficients C (:mod:`pkmcal.compensation.basis`):

* ``bed-mesh`` (a printer's bed): the bed surface sits w(x, y) above the model's bed plane,
  w a Klipper mesh of the bed's x, y; the probe triggers w early, which reads as the nozzle
  w *below* where the model puts it: δ = (0, 0, −w(P_xy)) at the probe point P. Klipper's
  bed_mesh adds w(nozzle x, y) to every commanded z (bed_mesh.py ``BedMesh.move``).
* ``pose-field`` (a hexapod's sag, a compliant machine): δ_c(x) = Σ_k C_kc φ_k(x) for each
  pose coordinate c it displaces (default: those the sensor sees, x, y, z and, for a sensor
  that reads the orientation, a, b, c), a polynomial in the whole pose: a sag that turns
  with the platform depends on its orientation as much as on its position (a polynomial
  in x, y, z alone predicted none of a simulated sag's unexplained part; docs/compensation.md).

The coefficients minimise Σ_j ‖L_j⁻¹ (r_j − H_j δ(x̂_j))‖² (L_j L_jᵀ = Cov e_j; generalised
least squares), plus μ ‖D C‖² with D the basis's roughness (second differences of a mesh, the
coefficients of a polynomial) and μ = 10⁻⁹ … 1 times the data's mean weight per coefficient
(:data:`SMOOTHING`): the smallest sets only what the data leave free (a mesh node no point
sees) to the smoothest continuation and moves what they determine by far less than the
noise (a mesh fitted back from its own heights to 10⁻⁷ mm,
tests/compensation/test_fit.py); the larger ones tame the nodes the data
barely see (a round bed's rim), whose heights noise would otherwise throw about.

**Complexity by cross-validation.** Candidates: no correction, then meshes of 3×3 … 7×7
(Klipper's probe counts: Lagrange at 3, bicubic above; a delta's round bed 3, 5, 7 over its
print radius, Klipper's round mesh), or polynomials of degree 0 … 3, each at every
smoothing level, ordered by the parameters they spend (the trace of the hat matrix,
:func:`effective_parameters`). The poses are split into k folds (k = 5, fewer with fewer poses; a seeded
permutation); each candidate is fitted on k − 1 folds and scored on the one left out, by
the whitened squared residual per pose. The chosen candidate is the simplest whose mean
score is within one standard error of the best (the one-standard-error rule, Hastie,
Tibshirani & Friedman, *Elements of Statistical Learning*, §7.10): a correction that fits
the noise is not chosen on a machine without a smooth error.

**The gate on held-out data.** The chosen field is refitted on all calibration poses and
applied to the held-out measurements (never seen by the calibration nor this fit): per pose,
d_j = s_j(before) − s_j(after) with s the whitened squared residual. The correction is kept
only when the held-out improvement is significant, mean(d) > 2 · sd(d)/√n (one-sided, about
2.3 % of keeping a useless correction by chance); the report gives before and after (RMS of
the readings, mm) and the decision with its reason.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pkmcal.compensation.basis import MeshBasis, PolynomialBasis, klipper_algorithm
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup

KINDS = ("bed-mesh", "pose-field")
#: Mesh sizes tried (nodes a side; Klipper's probe_count 3 … 7).
MESH_COUNTS = (3, 4, 5, 6, 7)
#: Polynomial degrees tried.
DEGREES = (0, 1, 2, 3)
#: Folds of the cross-validation (fewer when there are fewer poses).
FOLDS = 5
#: Relative weights of the roughness penalty tried (module docstring).
SMOOTHING = (1e-9, 1e-4, 1e-2, 1.0)
#: Standard errors the held-out improvement must exceed (one-sided).
GATE_Z = 2.0


@dataclass(frozen=True)
class Field:
    """A correction field (module docstring): ``kind`` (bed-mesh or pose-field),
    ``basis``, ``components`` (``("bed_z",)`` for a bed, else the pose coordinates it
    displaces) and ``coefficients`` (K, c), internal units (mm, rad)."""

    kind: str
    basis: MeshBasis | PolynomialBasis
    components: tuple[str, ...]
    coefficients: np.ndarray

    def bed_height(self, xy: np.ndarray) -> np.ndarray:
        """w (N,) mm: the bed surface above the model's bed plane at bed points x, y (bed-mesh)."""
        return self.basis.values(xy) @ self.coefficients[:, 0]

    def displacement(self, machine: Mechanism, poses: np.ndarray, at: np.ndarray | None = None) -> np.ndarray:
        """δ (N, n): where the real machine is relative to the model at ``poses`` (N, n);
        ``at`` (N, 2|3) the points the field is evaluated at (default: the poses' x, y, z;
        a bed mesh: the nozzle's x, y, over which it meets the bed)."""
        poses = machine.as_pose_array(poses)
        at = poses if at is None else np.asarray(at, dtype=float)
        out = np.zeros(poses.shape)
        phi = self.basis.values(at)
        if self.kind == "bed-mesh":
            out[:, machine.pose_names.index("z")] = -(phi @ self.coefficients[:, 0])
        else:
            idx = [machine.pose_names.index(c) for c in self.components]
            out[:, idx] = phi @ self.coefficients
        return out


@dataclass(frozen=True)
class Unexplained:
    """What the model leaves on a data set (module docstring): ``poses`` (N, n) the model's
    FK poses, ``points`` (N, 3|n) where the field is evaluated (the probe point for a bed,
    else the pose), ``residuals`` (N, m), ``H`` (N, m, n), ``whiten`` (N, m, m)
    L_j⁻¹, ``ok`` (N,) where the FK converged, ``lengths`` (m,) True for length readings."""

    poses: np.ndarray
    points: np.ndarray
    residuals: np.ndarray
    H: np.ndarray
    whiten: np.ndarray
    ok: np.ndarray
    lengths: np.ndarray
    pose_numbers: np.ndarray

    def subset(self, keep: np.ndarray) -> "Unexplained":
        return Unexplained(self.poses[keep], self.points[keep], self.residuals[keep], self.H[keep],
                           self.whiten[keep], self.ok[keep], self.lengths, self.pose_numbers[keep])


def unexplained(machine: Mechanism, setup: MeasurementSetup, measurements, kind: str) -> Unexplained:
    """:class:`Unexplained` of the calibrated ``machine`` with ``setup``'s (identified)
    sensor on ``measurements``; only the poses whose FK converged (the others are dropped)."""
    from pkmcal.identification.heldout import predict

    if machine.n_actuators != machine.n_dof:
        raise PkmcalError(f"machine '{machine.name}' is redundantly actuated: its measurements cannot be predicted "
                          "from the actuator readings by FK alone, so no correction is fitted for it")
    sensor = setup.sensor
    if sensor.reads_pose_pairs:
        raise PkmcalError("a correction is fitted to readings of single poses; printed-object distances read pairs: "
                          "fit it on the Z probe's measurements (their setup, e.g. z-probe-klipper, with --setup)")
    pred = predict(machine, sensor, measurements, "after")
    keep = np.flatnonzero(pred.ok & np.all(np.isfinite(pred.residuals), axis=1))
    if len(keep) == 0:
        raise PkmcalError("the calibrated machine's FK fails at every pose; check that the measurements belong to it")
    x = pred.poses[keep]
    frame = machine.frame(x)
    H = machine.pose_jacobian_from_twist(sensor.frame_jacobian(frame), x)
    if kind == "bed-mesh":
        if "touch-probe" not in sensor.abilities or "z" not in machine.pose_names:
            raise PkmcalError(f"a bed mesh is fitted from a Z probe's readings; the calibration's sensor is a "
                              f"'{sensor.kind}' sensor: fit a pose field instead (--field pose)")
        points = sensor.probe_points(frame)
    else:
        points = x
    A = machine.actuator_pose_jacobian(x)                                       # ∂q/∂x (N, l, n)
    G = np.linalg.solve(np.swapaxes(A, 1, 2), np.swapaxes(H, 1, 2)).swapaxes(1, 2)   # H A⁻¹ (N, m, l)
    sy = np.broadcast_to(np.asarray(setup.noise.reading_std, dtype=float), (sensor.n_readings,))
    sq = np.broadcast_to(np.asarray(setup.noise.actuator_std, dtype=float), (machine.n_actuators,))
    cov = np.einsum("nil,l,njl->nij", G, sq**2, G) + np.diag(sy**2)[None]
    if not np.all(np.linalg.eigvalsh(cov) > 0):
        raise PkmcalError("the setup's noise model gives some reading zero variance: a correction is weighed by the "
                          "noise; give the setup's noise (noise.reading, noise.actuator)")
    L = np.linalg.cholesky(cov)
    whiten = np.linalg.inv(L)
    lengths = ~np.asarray(sensor.reading_is_angle, dtype=bool)
    return Unexplained(x, points, pred.residuals[keep], H, whiten, np.ones(len(keep), dtype=bool), lengths,
                       np.asarray(measurements.pose_numbers, dtype=int)[keep])


def default_components(machine: Mechanism, sensor) -> tuple[str, ...]:
    """The pose coordinates a pose field displaces by default: all of them for a sensor that
    reads the pose, else the translations (a tracker sees a rotation only through its arm)."""
    if sensor.reads_pose() or not {"x", "y", "z"} <= set(machine.pose_names):
        return tuple(machine.pose_names)
    return ("x", "y", "z")


def _sensitivity(kind: str, components: tuple[str, ...], machine: Mechanism, data: Unexplained) -> np.ndarray:
    """S (N, m, c): ∂r/∂(field components) of each pose (module docstring)."""
    if kind == "bed-mesh":
        return -data.H[:, :, [machine.pose_names.index("z")]]
    return data.H[:, :, [machine.pose_names.index(c) for c in components]]


def _design(basis, S: np.ndarray, data: Unexplained) -> tuple[np.ndarray, np.ndarray]:
    """Whitened (A (N·m, K·c), b (N·m,)) of the linear model r = S Φ C (module docstring)."""
    phi = basis.values(data.points)                                                  # (N, K)
    A = np.einsum("nk,nic->nikc", phi, S)                                   # (N, m, K, c)
    A = np.einsum("nij,njkc->nikc", data.whiten, A).reshape(len(phi) * S.shape[1], -1)
    return A, _whitened(data).reshape(-1)


def _whitened(data: Unexplained) -> np.ndarray:
    """L_j⁻¹ r_j (N, m)."""
    return np.einsum("nij,nj->ni", data.whiten, data.residuals)


def _penalty(A: np.ndarray, D: np.ndarray, c: int, level: float) -> np.ndarray:
    """√μ (D ⊗ I_c), μ = ``level`` × the data's mean weight per coefficient."""
    mu = level * max(float(np.sum(A * A)) / A.shape[1], 1e-300)
    return np.sqrt(mu) * np.kron(D, np.eye(c))


def _solve(A: np.ndarray, b: np.ndarray, D: np.ndarray, c: int, level: float) -> np.ndarray:
    """C (K·c,) minimising ‖A C − b‖² + μ‖(D ⊗ I_c) C‖² (module docstring)."""
    P = _penalty(A, D, c, level)
    return np.linalg.lstsq(np.vstack([A, P]), np.concatenate([b, np.zeros(len(P))]), rcond=None)[0]


def effective_parameters(A: np.ndarray, D: np.ndarray, c: int, level: float) -> float:
    """trace of the fit's hat matrix, tr((AᵀA + PᵀP)⁺ AᵀA): the number of parameters the
    penalised fit spends (the coefficients' count without a penalty)."""
    P = _penalty(A, D, c, level)
    AtA = A.T @ A
    return float(np.trace(np.linalg.pinv(AtA + P.T @ P) @ AtA))


def _scores(A: np.ndarray, b: np.ndarray, C: np.ndarray | None, m: int) -> np.ndarray:
    """Whitened squared residual per pose (N,) of coefficients C (None: no correction)."""
    e = b if C is None else b - A @ C
    return np.sum(e.reshape(-1, m) ** 2, axis=1)


@dataclass(frozen=True)
class Candidate:
    """One complexity tried: ``label``, number of coefficients, cross-validated mean score
    per pose (whitened χ² per pose; ≈ readings per pose for a field that leaves only noise)
    and its standard error; ``smoothing`` the penalty's relative weight and ``dof`` the
    parameters it leaves the fit (:func:`effective_parameters`, the order of simplicity)."""

    label: str
    n_coefficients: int
    cv_score: float
    cv_se: float
    basis: MeshBasis | PolynomialBasis | None
    smoothing: float = 0.0
    dof: float = 0.0


def candidates(kind: str, machine: Mechanism, data: Unexplained, counts=MESH_COUNTS, degrees=DEGREES,
               bounds=None) -> list:
    """The bases tried, simplest first (None: no correction). A delta's round bed (its
    print radius) gets Klipper's round mesh (odd counts only, the nodes outside the radius
    repeating the row's ends, :class:`~pkmcal.compensation.basis.MeshBasis`)."""
    if kind == "bed-mesh":
        radius = round_bed_radius(machine) if bounds is None else None
        if radius is not None:
            r = radius
            return [None] + [MeshBasis(n, n, ((-r, r), (-r, r)), klipper_algorithm(n, n), radius=r)
                             for n in counts if n & 1]
        if bounds is None:
            lo = np.floor(data.points[:, :2].min(axis=0) * 10) / 10
            hi = np.ceil(data.points[:, :2].max(axis=0) * 10) / 10
            bounds = ((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))
        return [None] + [MeshBasis(n, n, bounds, klipper_algorithm(n, n)) for n in counts]
    box = tuple((float(lo), float(hi)) for lo, hi in zip(data.points.min(axis=0), data.points.max(axis=0)))
    return [None] + [PolynomialBasis(d, box) for d in degrees]


def round_bed_radius(machine: Mechanism) -> float | None:
    """A round bed's radius floored to 0.1 mm (Klipper's ``mesh_radius``, bed_mesh.py
    ``_init_mesh_config``) for a machine that declares a ``print_radius`` limit (a delta:
    its workspace box is ±that radius in x and y), None for other machines."""
    if "print_radius" not in machine.check_limits(machine.home_pose[None], margins=False).violations:
        return None
    radius = 0.5 * float(np.diff(machine.workspace_box()[0])[0])
    return float(np.floor(radius * 10) / 10)


def folds_of(n: int, k: int = FOLDS, seed: int = 0) -> np.ndarray:
    """(n,) the fold of each pose: a seeded permutation dealt round k folds (k ≤ n)."""
    k = max(2, min(k, n))
    fold = np.empty(n, dtype=int)
    fold[np.random.default_rng(seed).permutation(n)] = np.arange(n) % k
    return fold


def cross_validate(kind: str, components: tuple[str, ...], machine: Mechanism, data: Unexplained, bases: list,
                   k: int = FOLDS, seed: int = 0, levels=SMOOTHING) -> list[Candidate]:
    """Each basis's k-fold score at each smoothing level (module docstring), simplest (fewest
    effective parameters) first."""
    S = _sensitivity(kind, components, machine, data)
    m, c = S.shape[1], S.shape[2]
    n = len(data.poses)
    fold = folds_of(n, k, seed)
    rows = np.repeat(fold, m)
    out = []
    for basis in bases:
        if basis is None:
            per_pose = _scores(None, _whitened(data).reshape(-1), None, m)
            out.append(Candidate("no correction", 0, float(np.mean(per_pose)),
                                 float(np.std(per_pose, ddof=1) / np.sqrt(n)), None))
            continue
        A, b = _design(basis, S, data)
        D = basis.smoothing()
        for level in levels:
            per_pose = np.empty(n)
            for f in range(fold.max() + 1):
                C = _solve(A[rows != f], b[rows != f], D, c, level)
                per_pose[fold == f] = _scores(A[rows == f], b[rows == f], C, m)
            out.append(Candidate(f"{basis.label()}, smoothing {level:g}", basis.size * c, float(np.mean(per_pose)),
                                 float(np.std(per_pose, ddof=1) / np.sqrt(n)), basis, level,
                                 effective_parameters(A, D, c, level)))
    return sorted(out, key=lambda cand: cand.dof)


def one_standard_error(cands: list[Candidate]) -> int:
    """Index of the simplest candidate within one standard error of the best score."""
    best = int(np.argmin([c.cv_score for c in cands]))
    limit = cands[best].cv_score + cands[best].cv_se
    return next(i for i, c in enumerate(cands) if c.cv_score <= limit)


def fit_field(kind: str, components: tuple[str, ...], machine: Mechanism, data: Unexplained, basis,
              level: float = SMOOTHING[0]) -> Field:
    """The field of ``basis`` fitted on all of ``data`` with the smoothing ``level``."""
    S = _sensitivity(kind, components, machine, data)
    A, b = _design(basis, S, data)
    C = _solve(A, b, basis.smoothing(), S.shape[2], level).reshape(basis.size, S.shape[2])
    if isinstance(basis, MeshBasis) and basis.radius is not None:     # the full grid, as Klipper holds it
        C, basis = basis.expand(C), dataclasses.replace(basis, radius=None)
    return Field(kind, basis, tuple(components), C)


def field_residuals(fld: Field | None, machine: Mechanism, data: Unexplained) -> np.ndarray:
    """r − S Φ C (N, m): the readings' residuals left with the field (None: without one)."""
    if fld is None:
        return data.residuals
    S = _sensitivity(fld.kind, fld.components, machine, data)
    return data.residuals - np.einsum("nic,nc->ni", S, fld.basis.values(data.points) @ fld.coefficients)


@dataclass(frozen=True)
class Gate:
    """The held-out test (module docstring): RMS of the length readings before and after
    (mm), of the angle readings (deg, None without), the per-pose whitened improvement's
    mean and standard error, the number of poses, and the decision."""

    n_poses: int
    rms_before_mm: float
    rms_after_mm: float
    rms_before_deg: float | None
    rms_after_deg: float | None
    gain_mean: float
    gain_se: float
    accepted: bool


def gate(fld: Field, machine: Mechanism, held: Unexplained) -> Gate:
    """The held-out test of ``fld`` (module docstring)."""
    m = held.residuals.shape[1]
    before = _whitened(held)
    after_r = field_residuals(fld, machine, held)
    after = np.einsum("nij,nj->ni", held.whiten, after_r)
    d = _scores(None, before.reshape(-1), None, m) - _scores(None, after.reshape(-1), None, m)
    n = len(d)
    se = float(np.std(d, ddof=1) / np.sqrt(n)) if n > 1 else float("inf")

    def rms(r, cols, scale=1.0):
        return float(np.sqrt(np.mean(r[:, cols] ** 2)) * scale) if cols.any() else None

    ang = ~held.lengths
    return Gate(n, rms(held.residuals, held.lengths), rms(after_r, held.lengths),
                rms(held.residuals, ang, np.rad2deg(1.0)), rms(after_r, ang, np.rad2deg(1.0)),
                float(np.mean(d)), se, bool(n > 1 and np.mean(d) > GATE_Z * se))


@dataclass(frozen=True)
class CompensationReport:
    """What :func:`compensate` did: the candidates and their cross-validated scores, the
    chosen one, the field (None when none was chosen), the held-out gate (None when no
    field was chosen), the decision and its reason, and the pose counts."""

    kind: str
    candidates: tuple[Candidate, ...]
    chosen: int
    field: Field | None
    gate: Gate | None
    accepted: bool
    reason: str
    n_calibration: int
    n_heldout: int
    notes: tuple[str, ...] = field(default=())

    def to_dict(self) -> dict:
        out = {"kind": self.kind, "accepted": self.accepted, "reason": self.reason,
               "n_calibration_poses": self.n_calibration, "n_heldout_poses": self.n_heldout,
               "chosen": self.candidates[self.chosen].label,
               "candidates": [{"label": c.label, "n_coefficients": c.n_coefficients, "cv_score": c.cv_score,
                               "cv_se": c.cv_se, "smoothing": c.smoothing, "effective_parameters": c.dof}
                              for c in self.candidates]}
        if self.gate is not None:
            g = self.gate
            out["heldout"] = {"rms_before_mm": g.rms_before_mm, "rms_after_mm": g.rms_after_mm,
                              "rms_before_deg": g.rms_before_deg, "rms_after_deg": g.rms_after_deg,
                              "gain_mean": g.gain_mean, "gain_se": g.gain_se, "n_poses": g.n_poses}
        out["notes"] = list(self.notes)
        out["units"] = {"cv_score": "whitened squared residual per pose (about the readings per pose for pure noise)",
                        "gain_mean": "whitened squared residual per pose, before minus after"}
        return out

    def lines(self) -> list[str]:
        out = [f"cross-validation ({self.kind}, {self.n_calibration} calibration poses, score = whitened squared "
               "residual per pose, lower is better):"]
        for i, c in enumerate(self.candidates):
            mark = "  <- chosen (simplest within one standard error of the best)" if i == self.chosen else ""
            out.append(f"  {c.label:<42} {c.dof:6.1f} parameters  score {c.cv_score:10.4g} ± {c.cv_se:.2g}{mark}")
        if self.gate is not None:
            g = self.gate
            out.append(f"held-out ({g.n_poses} poses): reading RMS {g.rms_before_mm:.4g} mm before, "
                       f"{g.rms_after_mm:.4g} mm after the correction"
                       + (f"; angles {g.rms_before_deg:.4g} -> {g.rms_after_deg:.4g} deg"
                          if g.rms_before_deg is not None else ""))
            out.append(f"  improvement per pose {g.gain_mean:.4g} ± {g.gain_se:.2g} (whitened; kept when above "
                       f"{GATE_Z:g} standard errors)")
        out.append(("correction KEPT: " if self.accepted else "correction REJECTED: ") + self.reason)
        out.extend(f"note: {n}" for n in self.notes)
        return out


def compensate(machine: Mechanism, setup: MeasurementSetup, measurements, heldout, kind: str | None = None, *,
               counts=MESH_COUNTS, degrees=DEGREES, components: tuple[str, ...] | None = None,
               bounds=None, folds: int = FOLDS, seed: int = 0) -> CompensationReport:
    """Fit, choose and gate a correction of the calibrated ``machine`` with ``setup``'s
    identified sensor (module docstring): ``measurements`` the calibration data,
    ``heldout`` measurements no fit has seen. ``kind``: ``bed-mesh`` (default for a Z probe)
    or ``pose-field`` (default otherwise); ``components`` the pose coordinates a pose field
    displaces (default: :func:`default_components`); ``bounds`` a mesh's ((min_x, max_x), (min_y, max_y))."""
    sensor = setup.sensor
    if kind is None:
        kind = "bed-mesh" if "touch-probe" in sensor.abilities else "pose-field"
    if kind not in KINDS:
        raise PkmcalError(f"unknown correction kind '{kind}'; use one of {', '.join(KINDS)}")
    if components is None:
        components = ("bed_z",) if kind == "bed-mesh" else default_components(machine, sensor)
    elif kind == "pose-field":
        unknown = [c for c in components if c not in machine.pose_names]
        if unknown:
            raise PkmcalError(f"'{', '.join(unknown)}' is not a pose coordinate of machine '{machine.name}' "
                              f"({', '.join(machine.pose_names)})")
    if heldout is None:
        raise PkmcalError("a correction is kept only when held-out measurements show it helps: give held-out "
                          "measurements (poses measured like the calibration's, not used in it)")
    data = unexplained(machine, setup, measurements, kind)
    held = unexplained(machine, setup, heldout, kind)
    if len(data.poses) < 6:
        raise PkmcalError(f"{len(data.poses)} calibration poses: a correction needs at least 6 to cross-validate")
    bases = candidates(kind, machine, data, counts, degrees, bounds)
    cands = cross_validate(kind, components, machine, data, bases, folds, seed)
    chosen = one_standard_error(cands)
    n_cal, n_held = len(data.poses), len(held.poses)
    if cands[chosen].basis is None:
        return CompensationReport(kind, tuple(cands), chosen, None, None, False,
                                  "cross-validation chose no correction: no candidate predicts left-out calibration "
                                  "poses better than the calibrated model alone (beyond one standard error)",
                                  n_cal, n_held)
    fld = fit_field(kind, components, machine, data, cands[chosen].basis, cands[chosen].smoothing)
    g = gate(fld, machine, held)
    if g.accepted:
        reason = (f"{cands[chosen].label} lowers the held-out error by {g.gain_mean / g.gain_se:.3g} standard errors "
                  f"(reading RMS {g.rms_before_mm:.4g} -> {g.rms_after_mm:.4g} mm)")
    else:
        reason = (f"{cands[chosen].label} does not lower the held-out error significantly (improvement "
                  f"{g.gain_mean:.3g} ± {g.gain_se:.2g} per pose, needs {GATE_Z:g} standard errors): the "
                  "calibrated model alone is kept")
    return CompensationReport(kind, tuple(cands), chosen, fld, g, g.accepted, reason, n_cal, n_held)


__all__ = ["Candidate", "CompensationReport", "DEGREES", "Field", "GATE_Z", "KINDS", "MESH_COUNTS", "Unexplained",
           "round_bed_radius", "compensate", "cross_validate", "fit_field", "folds_of", "gate", "one_standard_error",
           "unexplained"]
