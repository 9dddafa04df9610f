"""ISO 9283 performance figures of a calibrated machine, with their GUM uncertainty, and the
accuracy a calibration predicts before anything is measured.

**Test pattern** (ISO 9283:1998 §6.2–6.3, as we read it). A cube of side s inside the
workspace, edges parallel to the base frame, centred where the machine works (here: the
centre of the planning workspace box, the other pose coordinates at home). The poses lie on
the diagonal plane C1–C2–C7–C8 (through the bottom edge C1–C2 and the opposite top edge
C7–C8): P1 at the cube's centre, P2…P5 on the plane's two diagonals at 10 % of the diagonal
from its corners (``CORNER_FRACTION``):

    C1 = c + s/2 (−1, −1, −1),  C2 = c + s/2 (+1, −1, −1),  C7 = c + s/2 (+1, +1, +1),
    C8 = c + s/2 (−1, +1, +1);  P1 = c,  P_i = c + 0.8 (C_k − c) for (P2, P3, P4, P5) ← (C1, C2, C7, C8)

so that P2–P4 and P3–P5 are opposite on a diagonal (the distance test uses P2–P4). Every
pose is visited in n = 30 cycles (``CYCLES``; §7.2.1), P1 … P5 in each. The cube is the
largest whose 3×3×3 grid and P1…P5 pass the planning checks (limits with the safety
margins, measurability; :func:`pkmcal.planning.candidates.check_candidates`).

**Pose characteristics** (§7.2, 7.3) of a pose with commanded (x_c, y_c, z_c, a_c, b_c, c_c)
and attained (x_j, …, c_j), j = 1…n; in terms of the errors e_j = attained_j − commanded
(angles wrapped):

    x̄ = (1/n) Σ x_j (ȳ, z̄, ā, b̄, c̄ likewise)
    AP_x = x̄ − x_c,  AP_y, AP_z;     AP_P = √(AP_x² + AP_y² + AP_z²)              (7.2.1)
    AP_a = ā − a_c,  AP_b, AP_c                                                    (7.2.1)
    l_j = √((x_j − x̄)² + (y_j − ȳ)² + (z_j − z̄)²),  l̄ = (1/n) Σ l_j,
    S_l = √(Σ (l_j − l̄)² / (n − 1)),     RP_l = l̄ + 3 S_l                         (7.2.2)
    RP_a = ±3 S_a,  S_a = √(Σ (a_j − ā)² / (n − 1))  (b, c likewise)              (7.2.2)

**Distance characteristics** (§7.5) between two poses 1, 2 of the pattern (P2 and P4):

    D_j = ‖p_1j − p_2j‖,  D_c = ‖p_c1 − p_c2‖,  D̄ = (1/n) Σ D_j
    AD_P = D̄ − D_c;   AD_x = (1/n) Σ |x_1j − x_2j| − |x_c1 − x_c2|  (y, z likewise)
    RD = ±3 S_D,  S_D = √(Σ (D_j − D̄)² / (n − 1))

(orientation distance figures are not computed).

**What is measured.** The tool point (TCP) and its frame, in the machine's base frame: the
instrument reads it in its own frame {W} (a laser tracker's point, a 6-D tracker's frame), and
the instrument's registration to the base frame, the sensor's ``world.*`` parameters
(:data:`REGISTRATION`), carries it there: p = R_wᵀ(y_p − p_w), R = R_wᵀ R(y_abc). The TCP
commanded is the commanded platform pose composed with the calibrated tool offset (full
pose ``tool.*``, a tracked point ``target.*``): p_c + R_c p̂_t, R_c R̂_t; that offset is part
of the command (the machine is told to put that point there), not of the measurement.
Orientation errors are the wrapped differences of the angles a, b, c (ISO 9283 compares
the angles). A tracked point gives the position figures only.

**Uncertainty** (GUM, JCGM 100:2008 §5, first order). Each figure F is a function of the
errors e (5 poses × n cycles × d coordinates); its analytic gradient g = ∂F/∂e is written
beside each formula in the code. The measured errors are e = e_true + ε + G δθ: ε the
instrument's noise on each reading (independent per reading, the setup's ``noise.reading``
σ, carried to the errors by K = ∂e/∂y: Σ_j = K_j Σ_y K_jᵀ), δθ the error of the
registration (common to every reading; covariance C_θ: the calibration's ``std`` of the
``world.*`` parameters, as a diagonal covariance, since the calibrated file keeps no
correlations between them; none when the frame was not estimated). Then

    u²(F) = Σ_j g_jᵀ Σ_j g_j + (Σ_j g_jᵀ G_j) C_θ (Σ_j G_jᵀ g_j),      U = k u, k = 2.

K and G by central differences of the closed-form error (:data:`STEP_MM`, :data:`STEP_RAD`).
The "true figure" is F(e_true): the machine's own performance in this test, free of the
instrument's error. A rigid registration error moves every attained pose alike, so it
changes AP and AD but not RP or RD. Two limits of first order are reported, not hidden:
AP_P is a norm, so where AP_P ≲ U its distribution is not Gaussian (flagged
``not-significant``: AP_P not distinguishable from 0); RP is biased upwards by the
instrument's own scatter, by about the RP an ideally repeatable machine would show,
RP_inst ≈ 3.616 σ_eq for isotropic noise (σ_eq = √(tr Σ/3); E l̄ = √(8/π) σ,
E S_l = √(3 − 8/π) σ for a χ₃ distance; 3 σ_a for RP_a); RP with RP_inst > 25 % of it is
flagged ``instrument-limited`` (ISO 9283 asks the instrument's uncertainty to stay below
25 % of the characteristic tested, as we read it). A simulated true machine
(``verify --real``) has exact poses: its figures carry U = 0.

**Predicted accuracy** (before anything is measured). A machine (true ρ, tool offset θ)
commanded through the calibrated model (ρ̂, θ̂) reaches x_r with IK(x_r, ρ) = IK(x_c, ρ̂),
so to first order (:func:`tool_error_jacobian`)

    δx = x_r − x_c = A⁻¹ B (ρ̂ − ρ),   A = ∂q/∂x,  B = ∂q/∂ρ,   δω = E(a, b, c) δx_abc
    δp_T = δx_xyz − [R p_t]× δω − R (p̂_t − p_t),   δω_T = δω − R E(t_abc)(t̂_abc − t_abc)

and Cov(δp_T, δω_T) = J C Jᵀ with C the parameters' covariance: for a plan, the
noise-model covariance (JᵀJ)⁻¹ of the whitened design Jacobian on the identifiable machine
and sensor parameters, the gauge the identifiability analysis suggests
(:func:`plan_covariance`); for a calibrated file, its machine covariance
(max(1, χ²/E[χ²]) · C_prior, :mod:`pkmcal.identification.uncertainty`), used only when the
calibration estimated no sensor parameter (the file keeps no machine–sensor covariance).
Along what the instrument cannot see (a tracked point: the platform's orientation; dial
indicators: x, y, c; a Z probe: the scale) the prediction depends on the gauge; a tracked
point's orientation bound is therefore not given. The position error's 95 % bound is the
quantile of ‖δp_T‖ for δp_T ~ N(0, S), S the 3×3 block, by Patnaik's approximation
‖δp‖² ≈ c χ²_ν with c = Σλ²/Σλ, ν = (Σλ)²/Σλ² (λ the eigenvalues of S; exact for equal λ
and for one nonzero λ); the orientation bound likewise for δω_T. This is the expected AP_P
of the machine at that pose: "with this plan and this instrument, expect ≤ X mm at 95 %
here".
"""

from __future__ import annotations

import math
import dataclasses
from dataclasses import dataclass, field

import numpy as np

from pkmcal.conventions import euler_rate_matrix, wrap_angle
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.base import Mechanism

#: Cycles per pose (ISO 9283 §7.2.1).
CYCLES = 30
#: P2…P5 lie at this fraction of the diagonal from its corners (ISO 9283 §6.3: (10 ± 2) %).
CORNER_FRACTION = 0.1
#: Coverage factor of the expanded uncertainty.
COVERAGE_FACTOR = 2.0
#: Pairs of pattern poses (1-based) of the distance characteristics.
DISTANCE_PAIRS = ((2, 4),)
#: RP_inst/RP above which a repeatability figure is instrument-limited (ISO 9283: 25 %).
INSTRUMENT_SHARE = 0.25
#: E[l̄ + 3 S_l]/σ for an isotropic 3-D Gaussian scatter of σ per axis (module docstring).
RP_PER_SIGMA = math.sqrt(8.0 / math.pi) + 3.0 * math.sqrt(3.0 - 8.0 / math.pi)
#: Grid points per cube edge checked when the cube is fitted in the workspace.
CUBE_GRID = 3


def _position_axes(mechanism: Mechanism) -> None:
    if tuple(mechanism.pose_names[:3]) != ("x", "y", "z"):
        raise PkmcalError(f"ISO 9283 figures are defined for machines with x, y, z pose coordinates; "
                          f"'{mechanism.name}' has {', '.join(mechanism.pose_names)}")


def _has_orientation(mechanism: Mechanism) -> bool:
    return tuple(mechanism.pose_names) == ("x", "y", "z", "a", "b", "c")


# -- the pattern -----------------------------------------------------------------------------


def cube_pattern(center: np.ndarray, side: float, fixed: np.ndarray) -> np.ndarray:
    """P1…P5 (5, n) of the cube of ``side`` centred at ``center`` (3,) on its diagonal plane
    C1–C2–C7–C8 (module docstring); the coordinates after x, y, z are those of ``fixed`` (n,)."""
    c = np.asarray(center, dtype=float)
    corners = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, 1], [-1, 1, 1]], dtype=float)   # C1, C2, C7, C8
    pts = np.vstack([c, c + (1.0 - 2.0 * CORNER_FRACTION) * 0.5 * side * corners])
    out = np.tile(np.asarray(fixed, dtype=float), (5, 1))
    out[:, :3] = pts
    return out


@dataclass(frozen=True)
class Iso9283Pattern:
    """The test pattern: ``poses`` (5, n) P1…P5 (mm, rad), the cube (``center`` (3,),
    ``side`` mm), ``cycles``; ``notes`` what fitting it in the workspace did."""

    poses: np.ndarray
    center: np.ndarray
    side: float
    cycles: int = CYCLES
    notes: tuple[str, ...] = ()

    def cycle_poses(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(poses (5·cycles, n), pose label 1…5, cycle 1…n)``: P1…P5 in every cycle."""
        label = np.tile(np.arange(1, 6), self.cycles)
        cycle = np.repeat(np.arange(1, self.cycles + 1), 5)
        return self.poses[label - 1], label, cycle


def iso9283_pattern(mechanism: Mechanism, setup=None, *, cycles: int = CYCLES, margin=None,
                    measurability=None) -> Iso9283Pattern:
    """The largest ISO 9283 test cube inside ``mechanism``'s workspace (module docstring):
    centred in the planning workspace box (:func:`~pkmcal.planning.candidates.workspace_box`),
    the pose coordinates after x, y, z at home, its side the largest (bisection) whose
    3×3×3 grid and P1…P5 pass the planning checks with ``margin`` (None: the machine's
    default safety margins, as ``pkmcal plan``) and the setup's measurability."""
    from pkmcal.planning.candidates import Measurability, _bisect_scale, check_candidates, workspace_box
    from pkmcal.planning.margins import planning_checks, resolve_margin

    _position_axes(mechanism)
    if int(cycles) < 2:
        raise PkmcalError(f"an ISO 9283 pattern needs at least 2 cycles (repeatability); got {cycles}")
    measurability = Measurability() if measurability is None else measurability
    reachable, notes = mechanism.within_geometry()
    notes = list(notes)
    if margin is None:
        margin = resolve_margin(reachable)
    checked, check_margin = planning_checks(reachable, margin)
    box = workspace_box(checked, setup, margin=check_margin, measurability=measurability, notes=notes)
    center = box[:3].mean(axis=1)
    fixed = np.asarray(mechanism.home_pose, dtype=float).copy()
    s_max = float(np.min(box[:3, 1] - box[:3, 0]))
    g = np.linspace(-0.5, 0.5, CUBE_GRID)
    grid = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)

    def poses_of(side: float) -> np.ndarray:
        cube = np.tile(fixed, (len(grid), 1))
        cube[:, :3] = center + side * grid
        return np.vstack([cube, cube_pattern(center, side, fixed)])

    def ok(t: float) -> bool:
        return bool(check_candidates(checked, setup, poses_of(t * s_max), margin=check_margin,
                                     measurability=measurability).ok.all())

    t = _bisect_scale(ok)
    if t * s_max <= 1e-6 * max(s_max, 1.0):
        raise PkmcalError(f"machine '{mechanism.name}': no ISO 9283 cube around {np.round(center, 3).tolist()} mm "
                          "passes the limits and the safety margins; check the home pose, the margins and the "
                          "sensor set-up")
    side = t * s_max
    return Iso9283Pattern(cube_pattern(center, side, fixed), center, float(side), int(cycles), tuple(notes))


def detect_pattern(mechanism: Mechanism, poses: np.ndarray, *, rtol: float = 1e-6
                   ) -> tuple[np.ndarray, np.ndarray] | str:
    """``(label (N,) 1…5, P1…P5 (5, n))`` when the commanded ``poses`` (N, n) are an ISO 9283
    pattern: five distinct poses, each repeated the same number of times (≥ 2), one
    orientation, P1 the centre of P2…P5, these the corners of a rectangle on a diagonal plane
    of an axis-parallel cube (edges 0.8 s along an axis and 0.8 s√2 along a face diagonal);
    P2…P5 numbered in order of first appearance, P4 the pose opposite P2. Otherwise the
    reason (one sentence). Poses equal to ``rtol`` × the largest |x|, |y|, |z| (lengths) and
    to ``rtol`` rad (angles) are the same pose."""
    poses = np.asarray(poses, dtype=float)
    if tuple(mechanism.pose_names[:3]) != ("x", "y", "z") or len(poses) < 10:
        return "not five poses repeated in cycles"
    scale = max(1.0, float(np.max(np.abs(poses[:, :3]))))
    unit = np.where(np.arange(poses.shape[1]) < 3, scale, 1.0)          # lengths by their scale, angles (rad)
    key = np.round(poses / (rtol * unit)).astype(np.int64)
    uniq, first, inverse, counts = np.unique(key, axis=0, return_index=True, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    if len(uniq) != 5:
        return f"{len(uniq)} distinct poses, not the 5 of the ISO 9283 pattern"
    if len(set(counts.tolist())) != 1:
        return f"the 5 poses are repeated {sorted(counts.tolist())} times, not the same number of cycles each"
    order = np.argsort(first)                          # groups in order of first appearance
    pts = poses[first[order]]
    if np.ptp(pts[:, 3:], axis=0).max(initial=0.0) > rtol:
        return "the 5 poses do not share one orientation"
    p = pts[:, :3]
    centre_of = np.array([np.abs(p[i] - np.delete(p, i, axis=0).mean(axis=0)).max() for i in range(5)])
    i1 = int(np.argmin(centre_of))
    tol = 2.0 * rtol * scale                           # the keys' rounding, twice
    if centre_of[i1] > tol:
        return "no pose is the centre of the other four"
    rest = [i for i in range(5) if i != i1]
    v = p[rest] - p[i1]
    opposite = [int(np.argmin(np.abs(v + v[0]).max(axis=1)))]
    if np.abs(v[opposite[0]] + v[0]).max() > tol:
        return "the four outer poses are not opposite in pairs about the centre"
    others = [k for k in range(1, 4) if k != opposite[0]]
    a, b = v[0], v[others[0]]
    if np.abs(v[others[1]] + b).max() > tol:
        return "the four outer poses are not opposite in pairs about the centre"
    e1, e2 = a - b, a + b                                # the rectangle's two edges
    l1, l2 = np.linalg.norm(e1), np.linalg.norm(e2)
    short, long_ = (e1, e2) if l1 <= l2 else (e2, e1)
    ls, ll = min(l1, l2), max(l1, l2)
    # the short edge along one axis, the long one along a face diagonal (one zero component)
    if ls <= tol or abs(ll / ls - math.sqrt(2.0)) > 1e-4 or abs(float(short @ long_)) > 1e-6 * ll * ls \
            or np.sort(np.abs(short))[1] > 1e-6 * ls or np.sort(np.abs(long_))[0] > 1e-6 * ll:
        return "the outer poses are not on a diagonal plane of an axis-parallel cube"
    # labels: P1 the centre; P2 the first outer pose, P4 its opposite, P3 the next, P5 its opposite
    outer = [rest[0], rest[others[0]], rest[opposite[0]], rest[others[1]]]
    group_label = np.empty(5, dtype=int)
    group_label[order[i1]] = 1
    for lab, i in zip((2, 3, 4, 5), outer):
        group_label[order[i]] = lab
    label = group_label[inverse]
    commanded = np.empty((5, poses.shape[1]))
    for g in range(5):
        commanded[group_label[g] - 1] = poses[first[g]]
    return label, commanded


# -- the figures -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Figure:
    """One ISO 9283 figure: ``name`` (AP_P, AP_x, RP_l, AD_P, …), ``pose`` ("P1", "P2-P4"),
    ``value`` and expanded uncertainty ``U`` (k = 2) in internal units (mm, rad), ``unit``
    ("mm" or "rad"); ``note`` a flag (``not-significant``, ``instrument-limited``) or ""."""

    name: str
    pose: str
    value: float
    U: float
    unit: str
    note: str = ""

    def to_dict(self) -> dict:
        deg = self.unit == "rad"
        f = float(np.rad2deg(1.0)) if deg else 1.0
        unit = "deg" if deg else "mm"
        return {"figure": self.name, "pose": self.pose, f"value_{unit}": self.value * f, f"U_{unit}": self.U * f,
                "k": COVERAGE_FACTOR, "note": self.note or None}


@dataclass(frozen=True)
class Iso9283Report:
    """The figures of an ISO 9283 test (:class:`Figure`), how their uncertainty was
    propagated (``uncertainty``: one sentence), the cycles, and per pose the 95 % bound of
    AP_P the calibration's covariance predicts (``predicted_mm``, or None)."""

    figures: tuple[Figure, ...]
    cycles: int
    uncertainty: str
    predicted_mm: tuple[float, ...] | None = None
    notes: tuple[str, ...] = field(default_factory=tuple)
    #: the key of ``verify --json`` that holds it
    json_key = "iso9283"

    def get(self, name: str, pose: str) -> Figure:
        for f in self.figures:
            if f.name == name and f.pose == pose:
                return f
        raise KeyError((name, pose))

    def to_dict(self) -> dict:
        out = {"standard": "ISO 9283:1998 pose (7.2) and distance (7.5) characteristics", "cycles": self.cycles,
               "coverage_factor": COVERAGE_FACTOR, "uncertainty": self.uncertainty,
               "figures": [f.to_dict() for f in self.figures], "notes": list(self.notes)}
        if self.predicted_mm is not None:
            out["predicted_AP_P_95_mm"] = {f"P{i + 1}": v for i, v in enumerate(self.predicted_mm)}
        return out

    def format_table(self) -> str:
        """A table: one row per figure, one column per pose (or pair), ``value ± U`` in
        the row's unit (µm below 0.1 mm, else mm; arcseconds below 0.01°, else degrees)."""
        poses = list(dict.fromkeys(f.pose for f in self.figures))
        names = list(dict.fromkeys(f.name for f in self.figures))
        exact = all(f.U == 0 for f in self.figures)
        head = f"ISO 9283 (P1..P5 of the test cube, {self.cycles} cycles): " + \
            ("exact values" if exact else "value +- U (k = 2)")
        rows = [["figure", *poses]]
        for name in names:
            figs = {f.pose: f for f in self.figures if f.name == name}
            big = max(max(abs(f.value), f.U) for f in figs.values())
            if figs[next(iter(figs))].unit == "mm":
                unit, scale, fmt = ("mm", 1.0, "{:.4f}") if big >= 0.1 else ("µm", 1e3, "{:.2f}")
            else:
                unit, scale, fmt = ("deg", float(np.rad2deg(1.0)), "{:.4f}") if np.rad2deg(big) >= 0.01 else \
                    ("arcsec", float(np.rad2deg(1.0)) * 3600.0, "{:.2f}")
            cells = []
            for pose in poses:
                f = figs.get(pose)
                if f is None:
                    cells.append("")
                    continue
                text = fmt.format(float(fmt.format(f.value * scale)) + 0.0)      # no "-0.00"
                if not exact:
                    text += " +- " + fmt.format(f.U * scale)
                cells.append(text + ("*" if f.note else ""))
            rows.append([f"{name} ({unit})", *cells])
        width = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        lines = [head] + ["  " + "  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, width)))
                          for r in rows]
        flagged = sorted({(f.name, f.note) for f in self.figures if f.note})
        for name, note in flagged:
            why = {"not-significant": "AP_P within its U of 0: not distinguishable from 0 (first order fails there)",
                   "instrument-limited": "the instrument alone would show more than 25 % of this repeatability"}[note]
            lines.append(f"  * {name}: {why}")
        if self.predicted_mm is not None:
            lines.append("  predicted before measuring (95 %, the calibrated file's covariance max(1, chi2/E[chi2]) x "
                         "C_prior): AP_P <= " + ", ".join(
                f"P{i + 1} {1e3 * v:.2f} µm" if v < 0.1 else f"P{i + 1} {v:.4f} mm"
                for i, v in enumerate(self.predicted_mm)))
        lines.append(f"  uncertainty: {self.uncertainty}")
        lines.extend(f"  note: {n}" for n in self.notes)
        return "\n".join(lines)


def _std(x: np.ndarray) -> np.ndarray:
    """Sample standard deviation (ddof 1) over axis −1."""
    return np.sqrt(np.sum((x - x.mean(axis=-1, keepdims=True)) ** 2, axis=-1) / (x.shape[-1] - 1))


def _safe(x: np.ndarray) -> np.ndarray:
    return np.where(x > 0, x, 1.0)


def figures_with_gradients(errors: np.ndarray, commanded: np.ndarray, pairs=DISTANCE_PAIRS) -> list[tuple]:
    """Every figure of the module docstring with its gradient, for errors ``e`` (..., 5, n, d)
    (d = 3 positions, or 6 with the orientation angles, rad; any leading batch axes, e.g.
    Monte Carlo campaigns) at the commanded P1…P5 (5, ≥ 3): ``[(name, pose, value (...),
    unit, {pose index: ∂F/∂e_pose (..., n, d)})]`` (a figure depends on one or two poses'
    rows only)."""
    e = np.asarray(errors, dtype=float)
    *batch, P, n, d = e.shape
    if n < 2:
        raise PkmcalError("ISO 9283 repeatability needs at least 2 cycles per pose")
    cmd = np.asarray(commanded, dtype=float)
    out = []

    def unit_grad(k: int) -> np.ndarray:
        g = np.zeros((*batch, n, d))
        g[..., k] = 1.0 / n                                        # ∂ē_k/∂e_jk = 1/n
        return g

    for i in range(P):
        pose = f"P{i + 1}"
        ep = e[..., i, :, :3]
        mean = ep.mean(axis=-2)                                   # (..., 3)
        ap = np.linalg.norm(mean, axis=-1)
        g = np.zeros((*batch, n, d))
        g[..., :3] = (mean / (n * _safe(ap))[..., None])[..., None, :] * (ap > 0)[..., None, None]
        out.append(("AP_P", pose, ap, "mm", {i: g}))               # ∂|ē|/∂e_j = ē/(n|ē|)
        for k, axis in enumerate("xyz"):
            out.append((f"AP_{axis}", pose, mean[..., k], "mm", {i: unit_grad(k)}))
        if d == 6:
            mo = e[..., i, :, 3:].mean(axis=-2)
            for k, axis in enumerate("abc"):
                out.append((f"AP_{axis}", pose, mo[..., k], "rad", {i: unit_grad(3 + k)}))
        dev = ep - mean[..., None, :]
        lj = np.linalg.norm(dev, axis=-1)                          # (..., n)
        u = dev / _safe(lj)[..., None]
        lbar = lj.mean(axis=-1)
        S = _std(lj)
        # ∂l̄/∂e_k = (u_k − ū)/n;  ∂S_l/∂e_k = [(l_k − l̄) u_k − (1/n) Σ_j (l_j − l̄) u_j] / ((n − 1) S_l)
        g = np.zeros((*batch, n, d))
        w = (lj - lbar[..., None])[..., None] * u
        g[..., :3] = (u - u.mean(axis=-2, keepdims=True)) / n + \
            3.0 * (w - w.mean(axis=-2, keepdims=True)) / ((n - 1) * _safe(S))[..., None, None]
        out.append(("RP_l", pose, lbar + 3.0 * S, "mm", {i: g}))
        if d == 6:
            for k, axis in enumerate("abc"):
                a = e[..., i, :, 3 + k]
                sa = _std(a)
                g = np.zeros((*batch, n, d))
                g[..., 3 + k] = 3.0 * (a - a.mean(axis=-1, keepdims=True)) / ((n - 1) * _safe(sa))[..., None]
                out.append((f"RP_{axis}", pose, 3.0 * sa, "rad", {i: g}))   # ∂(3 S_a)/∂a_k
    for i1, i2 in pairs:
        if max(i1, i2) > P:
            continue
        pose = f"P{i1}-P{i2}"
        dc = cmd[i1 - 1, :3] - cmd[i2 - 1, :3]
        vec = dc + e[..., i1 - 1, :, :3] - e[..., i2 - 1, :, :3]  # p_1j − p_2j (..., n, 3)
        D = np.linalg.norm(vec, axis=-1)
        w = vec / D[..., None]

        def pair(gp: np.ndarray) -> dict:                          # ∂/∂e_2j = −∂/∂e_1j
            g = np.zeros((*batch, n, d))
            g[..., :3] = gp
            return {i1 - 1: g, i2 - 1: -g}

        out.append(("AD_P", pose, D.mean(axis=-1) - np.linalg.norm(dc), "mm", pair(w / n)))
        for k, axis in enumerate("xyz"):
            gp = np.zeros(vec.shape)
            gp[..., k] = np.sign(vec[..., k]) / n
            out.append((f"AD_{axis}", pose, np.abs(vec[..., k]).mean(axis=-1) - abs(dc[k]), "mm", pair(gp)))
        SD = _std(D)
        gp = 3.0 * (D - D.mean(axis=-1, keepdims=True))[..., None] * w / ((n - 1) * _safe(SD))[..., None, None]
        out.append(("RD", pose, 3.0 * SD, "mm", pair(gp)))          # ∂(3 S_D)/∂e_1j
    return out


def figure_arrays(errors: np.ndarray, commanded: np.ndarray, *, row_cov: np.ndarray | None = None,
                  common: np.ndarray | None = None, common_cov: np.ndarray | None = None, pairs=DISTANCE_PAIRS
                  ) -> list[tuple[str, str, np.ndarray, np.ndarray, str]]:
    """``[(name, pose, value (...), U (...), unit)]`` of :func:`figures_with_gradients` with
    the GUM expanded uncertainty U = 2 u (module docstring), over any leading batch axes of
    ``errors`` (..., 5, n, d), ``row_cov`` (..., 5, n, d, d) and ``common`` (..., 5, n, d, k)."""
    out = []
    for name, pose, value, unit, grads in figures_with_gradients(errors, commanded, pairs):
        var = np.zeros(np.shape(value))
        if row_cov is not None:
            for i, g in grads.items():
                var = var + np.einsum("...ni,...nij,...nj->...", g, row_cov[..., i, :, :, :], g)
        if common is not None and common_cov is not None:
            s = sum(np.einsum("...ni,...nik->...k", g, common[..., i, :, :, :]) for i, g in grads.items())
            var = var + np.einsum("...k,kl,...l->...", s, common_cov, s)
        out.append((name, pose, value, COVERAGE_FACTOR * np.sqrt(np.clip(var, 0.0, None)), unit))
    return out


def iso9283_figures(errors: np.ndarray, commanded: np.ndarray, *, row_cov: np.ndarray | None = None,
                    common: np.ndarray | None = None, common_cov: np.ndarray | None = None,
                    pairs=DISTANCE_PAIRS, uncertainty: str = "", predicted_mm=None,
                    notes: tuple[str, ...] = ()) -> Iso9283Report:
    """The ISO 9283 figures (module docstring) of ``errors`` (5, n, d) = attained −
    commanded (mm, rad; d = 3 or 6) at the commanded P1…P5 (5, ≥ 3), with their expanded
    uncertainty U = 2 u: ``row_cov`` (5, n, d, d) the covariance of each row's error from
    the instrument's noise, ``common`` (5, n, d, k) ∂e/∂θ of the registration parameters θ
    common to all rows and ``common_cov`` (k, k) their covariance (both None: no
    registration error). Without ``row_cov`` the figures are exact (U = 0)."""
    e = np.asarray(errors, dtype=float)
    rp_inst = {}
    if row_cov is not None:                   # the RP an ideally repeatable machine would show, per pose
        rc = np.asarray(row_cov)
        rp_inst["RP_l"] = RP_PER_SIGMA * np.sqrt(np.trace(rc[:, :, :3, :3], axis1=-2, axis2=-1).mean(axis=1) / 3.0)
        for k, axis in enumerate("abc" if e.shape[-1] == 6 else ""):
            rp_inst[f"RP_{axis}"] = 3.0 * np.sqrt(rc[:, :, 3 + k, 3 + k].mean(axis=1))
    figs = []
    for name, pose, value, U, unit in figure_arrays(e, commanded, row_cov=row_cov, common=common,
                                                    common_cov=common_cov, pairs=pairs):
        value, U = float(value), float(U)
        note = ""
        if name == "AP_P" and U > 0 and value <= U:
            note = "not-significant"
        if name in rp_inst and rp_inst[name][int(pose[1:]) - 1] > INSTRUMENT_SHARE * value:
            note = "instrument-limited"
        figs.append(Figure(name, pose, value, U, unit, note))
    return Iso9283Report(tuple(figs), e.shape[1], uncertainty,
                         None if predicted_mm is None else tuple(map(float, predicted_mm)), tuple(notes))


def arrange(label: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Rows of ``values`` (N, ...) grouped by pattern pose: (5, n, ...) in the order of the
    rows within each pose (the cycles)."""
    label = np.asarray(label)
    groups = [np.flatnonzero(label == k) for k in range(1, 6)]
    if len({len(g) for g in groups}) != 1:
        raise PkmcalError("the ISO 9283 poses are not measured in the same number of cycles each "
                          f"({', '.join(f'P{k + 1}: {len(g)}' for k, g in enumerate(groups))}); measure every pose "
                          "in every cycle")
    return np.stack([np.asarray(values)[g] for g in groups])


def pose_errors(mechanism: Mechanism, attained: np.ndarray, commanded: np.ndarray) -> np.ndarray:
    """``attained − commanded`` (N, d) in the coordinates ISO 9283 compares: x, y, z (mm)
    and, for a machine with a, b, c, the wrapped angle differences (rad)."""
    _position_axes(mechanism)
    d = 6 if _has_orientation(mechanism) else 3
    e = np.asarray(attained, dtype=float)[:, :d] - np.asarray(commanded, dtype=float)[:, :d]
    if d == 6:
        e[:, 3:] = wrap_angle(e[:, 3:])
    return e


# -- measured with an instrument ---------------------------------------------------------------


#: Central-difference steps of the instrument's inverse: mm for lengths, rad for angles.
#: Truncation ~h²‖g‴‖/6 (curvature 1/L, L ≳ 10 mm: < 1e-10 mm) against rounding ~ε|x|/h
#: (|x| ≲ 1e3 mm: < 1e-9 mm); both far below any instrument's σ.
STEP_MM, STEP_RAD = 1e-4, 1e-6


#: The instrument's registration to the machine's base frame: the sensor parameters whose
#: covariance the measured figures' uncertainty carries (the tool/target offset is not: it
#: defines the tool point commanded, exact by definition of the command).
REGISTRATION = tuple(f"world.{c}" for c in "xyzabc")


def _tool_point(mechanism: Mechanism, sensor) -> tuple[list[int], list[int]] | None:
    """Indices of the sensor's tool offset (position, rotation) in its parameters: full pose
    ``tool.*`` (position and rotation), a tracked point ``target.*`` (position); None for
    an instrument that reads neither the pose nor a point of the platform."""
    names = list(sensor.param_names)
    if sensor.invertible and _has_orientation(mechanism) and all(f"tool.{c}" in names for c in "xyzabc"):
        return [names.index(f"tool.{c}") for c in "xyz"], [names.index(f"tool.{c}") for c in "abc"]
    if sensor.kind == "position" and all(f"target.{c}" in names for c in "xyz"):
        return [names.index(f"target.{c}") for c in "xyz"], []
    return None


def measured_errors(mechanism: Mechanism, sensor, readings: np.ndarray, commanded: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(e (N, d), K (N, d, m), G (N, d, k))``: the errors of the tool point (TCP) the
    instrument reads, in the base frame, against the TCP commanded, at the ``commanded``
    poses (N, n), and their derivatives by central differences with respect to the readings
    y (m) and the sensor's parameters θ (k). Full pose: attained p = R_wᵀ(y_p − p_w),
    R = R_wᵀ R(y_abc), commanded p_c + R_c p_t, R_c R_t (orientation errors: wrapped
    differences of the angles a, b, c); a tracked point: the point only (d = 3)."""
    from pkmcal.conventions import euler_to_matrix, matrix_to_euler

    _position_axes(mechanism)
    tool = _tool_point(mechanism, sensor)
    if tool is None:
        raise PkmcalError(f"ISO 9283 figures need an instrument that reads the pose or a point of the platform "
                          f"(full-pose, position); the setup's '{sensor.kind}' sensor reads neither")
    names = list(sensor.param_names)
    iw = [names.index(n) for n in REGISTRATION]
    it, ir = tool
    f_c = mechanism.frame(np.asarray(commanded, dtype=float))
    y0 = np.asarray(readings, dtype=float)
    theta0 = np.asarray(sensor.params, dtype=float)

    def err(y, theta):
        Rw = euler_to_matrix(theta[iw[3:]])
        e = (y[:, :3] - theta[iw[:3]]) @ Rw - (f_c.p + np.einsum("nij,j->ni", f_c.R, theta[it]))
        if not ir:
            return e
        R_att = np.einsum("ji,njk->nik", Rw, euler_to_matrix(y[:, 3:6]))
        R_cmd = f_c.R @ euler_to_matrix(theta[ir])
        return np.hstack([e, wrap_angle(matrix_to_euler(R_att) - matrix_to_euler(R_cmd))])

    e0 = err(y0, theta0)
    steps_y = np.where(np.asarray(sensor.reading_is_angle, dtype=bool), STEP_RAD, STEP_MM)
    steps_t = np.where(np.asarray(sensor.param_is_angle, dtype=bool), STEP_RAD, STEP_MM)
    K = np.empty(e0.shape + (y0.shape[1],))
    for i, h in enumerate(steps_y):
        dy = np.zeros(y0.shape[1])
        dy[i] = h
        K[:, :, i] = (err(y0 + dy, theta0) - err(y0 - dy, theta0)) / (2 * h)
    G = np.empty(e0.shape + (len(theta0),))
    for i, h in enumerate(steps_t):
        dt = np.zeros(len(theta0))
        dt[i] = h
        G[:, :, i] = (err(y0, theta0 + dt) - err(y0, theta0 - dt)) / (2 * h)
    return e0, K, G


def measured_report(mechanism: Mechanism, setup, readings: np.ndarray, commanded: np.ndarray, label: np.ndarray, *,
                    sensor_cov: np.ndarray | None = None, covariance_note: str = "",
                    machine_covariance: np.ndarray | None = None) -> Iso9283Report:
    """:func:`iso9283_figures` of an ISO 9283 test measured by ``setup``'s instrument: rows
    ``readings`` (N, m) at the ``commanded`` poses (N, n), pattern pose ``label`` (N,) 1…5.
    The instrument's noise is the setup's ``noise.reading`` σ; the registration's
    covariance ``sensor_cov`` (k, k) over the sensor's parameters (zero rows for those
    held; None: no registration error), described by ``covariance_note``. With
    ``machine_covariance`` (p, p) the report carries the AP_P each pose was predicted to
    have (:func:`predicted_accuracy`)."""
    e, K, G = measured_errors(mechanism, setup.sensor, readings, commanded)
    sy = np.broadcast_to(np.asarray(setup.noise.reading_std, dtype=float), (K.shape[-1],))
    row_cov = np.einsum("nim,m,njm->nij", K, sy ** 2, K)
    cmd5 = arrange(label, commanded)[:, 0]
    common = None if sensor_cov is None else arrange(label, G)
    sigma = ", ".join(f"{name} {v:.3g} {'rad' if ang else 'mm'}" for name, v, ang in
                      zip(setup.sensor.reading_names, sy, setup.sensor.reading_is_angle))
    what = f"instrument noise ({setup.noise.distribution}; the setup's noise.reading sigma: {sigma})"
    if sensor_cov is not None:
        what += f" and the registration of the instrument ({covariance_note or 'its identified covariance'})"
    predicted = None
    if machine_covariance is not None:      # the tool point (its offset exact: the sensor's rows zero)
        p = len(machine_covariance)
        joint = np.zeros((p + len(setup.sensor.params),) * 2)
        joint[:p, :p] = machine_covariance
        predicted = predicted_accuracy(mechanism, joint, cmd5, sensor=setup.sensor).position
    return iso9283_figures(arrange(label, e), cmd5, row_cov=arrange(label, row_cov), common=common,
                           common_cov=sensor_cov, uncertainty="GUM first order, k = 2, from the " + what,
                           predicted_mm=predicted)


# -- predicted before measuring ---------------------------------------------------------------


def tool_error_jacobian(mechanism: Mechanism, poses: np.ndarray, sensor=None) -> np.ndarray:
    """∂(δp_T, δω_T)/∂(ρ̂ − ρ, θ̂ − θ) (N, 6 or 3, p [+ k]): the error of the tool point (and
    the rotation vector of its frame, base frame), attained − commanded, of a machine (true
    parameters ρ, tool offset θ) commanded through a model (ρ̂, and with ``sensor`` the tool
    offset θ̂ in the sensor's parameters): IK(x_r, ρ) = IK(x_c, ρ̂), so

        δx = A⁻¹ B (ρ̂ − ρ),  δp = δx_xyz,  δω = E(a, b, c) δx_abc
        δp_T = δp − [R p_t]× δω − R (p̂_t − p_t),    δω_T = δω − R E(t_abc) (t̂_abc − t_abc)

    (world.* columns zero: the instrument's registration is not the machine's error)."""
    if mechanism.n_actuators != mechanism.n_dof:
        raise PkmcalError(f"machine '{mechanism.name}' has {mechanism.n_actuators} actuators for {mechanism.n_dof} "
                          "pose coordinates: its accuracy is not predicted from the inverse kinematics alone")
    _position_axes(mechanism)
    poses = mechanism.as_pose_array(poses)
    A, B = mechanism.actuator_jacobians(poses)
    M = np.linalg.solve(A, B)                                         # δx = A⁻¹ B δρ (N, n, p)
    N, p = len(poses), B.shape[-1]
    rot = _has_orientation(mechanism)
    d = 6 if rot else 3
    k = 0 if sensor is None else len(sensor.params)
    J = np.zeros((N, d, p + k))
    J[:, :3, :p] = M[:, :3]
    if rot:
        J[:, 3:, :p] = euler_rate_matrix(poses[:, 3:6]) @ M[:, 3:]
    tool = None if sensor is None else _tool_point(mechanism, sensor)
    if tool is not None and tool != ([], []):
        it, ir = tool
        theta = np.asarray(sensor.params, dtype=float)
        R = mechanism.frame(poses).R
        if rot:
            v = R @ theta[it]                                          # R p_t (N, 3)
            cross = np.zeros((N, 3, 3))                                # −[v]×
            cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = v[:, 2], -v[:, 1], v[:, 0]
            cross[:, 1, 0], cross[:, 2, 0], cross[:, 2, 1] = -v[:, 2], v[:, 1], -v[:, 0]
            J[:, :3, :p] += cross @ J[:, 3:, :p]
        J[:, :3, [p + i for i in it]] = -R
        if ir:
            J[:, 3:, [p + i for i in ir]] = -R @ euler_rate_matrix(theta[ir])
    return J


def norm_quantile(cov: np.ndarray, level: float = 0.95) -> np.ndarray:
    """The ``level`` quantile (N,) of ‖v‖ for v ~ N(0, cov) (N, 3, 3), Patnaik's
    approximation ‖v‖² ≈ c χ²_ν (module docstring)."""
    from scipy.stats import chi2

    lam = np.clip(np.linalg.eigvalsh(np.asarray(cov, dtype=float)), 0.0, None)
    s1, s2 = lam.sum(axis=-1), (lam ** 2).sum(axis=-1)
    pos = s2 > 0
    c = np.where(pos, s2 / np.where(pos, s1, 1.0), 0.0)
    nu = np.where(pos, s1 ** 2 / np.where(pos, s2, 1.0), 1.0)
    return np.sqrt(c * chi2.ppf(level, nu))


@dataclass(frozen=True)
class PredictedAccuracy:
    """The ``level`` bounds of the position error (mm) and of the rotation angle (rad, or
    None) at each of ``poses`` (N, n) that the covariance predicts (module docstring)."""

    poses: np.ndarray
    position: np.ndarray
    orientation: np.ndarray | None
    level: float = 0.95


def predicted_accuracy(mechanism: Mechanism, covariance: np.ndarray, poses: np.ndarray, level: float = 0.95,
                       sensor=None) -> PredictedAccuracy:
    """The accuracy a calibration with parameter ``covariance`` predicts at ``poses`` (module
    docstring): the ``level`` quantiles of the tool point's position error ‖δp_T‖ and of its
    rotation angle ‖δω_T‖ (:func:`tool_error_jacobian`). ``covariance`` (p, p) over the
    machine's parameters (the platform frame's origin), or with ``sensor`` (p + k, p + k)
    over the machine's and the sensor's parameters (the tool point its tool offset defines;
    no orientation bound when the sensor reads no rotation: a tracked point leaves the
    platform's orientation to the gauge)."""
    J = tool_error_jacobian(mechanism, poses, sensor)
    C = np.asarray(covariance, dtype=float)
    if C.shape != (J.shape[-1],) * 2:
        raise PkmcalError(f"a covariance of machine '{mechanism.name}'" + (" and its sensor" if sensor else "")
                          + f" is {J.shape[-1]} x {J.shape[-1]}; got {C.shape}")
    S = J @ C @ np.swapaxes(J, 1, 2)
    reads_rotation = sensor is None or bool((_tool_point(mechanism, sensor) or ([], []))[1])
    ori = norm_quantile(S[:, 3:, 3:], level) if J.shape[1] == 6 and reads_rotation else None
    return PredictedAccuracy(mechanism.as_pose_array(poses), norm_quantile(S[:, :3, :3], level), ori, level)


def plan_covariance(mechanism: Mechanism, setup, poses: np.ndarray, method: str | None = None,
                    report=None) -> np.ndarray:
    """The covariance (p + k, p + k) of the machine's and the sensor's parameters a
    calibration on ``poses`` with ``setup`` would have, from the noise model alone: (JᵀJ)⁻¹
    of the whitened design Jacobian
    (:func:`~pkmcal.identification.identifiability.design_jacobian`) on the candidate
    parameters less the gauge the identifiability analysis suggests, zero rows for
    parameters not estimated (a session's offsets marginalised).
    ``report``: the :class:`~pkmcal.identification.identifiability.IdentifiabilityReport` of
    these poses and ``method`` when already computed (its candidates: a ``free``/``fix``
    choice)."""
    from pkmcal.identification.identifiability import design_jacobian, identifiability
    from pkmcal.identification.residuals import default_method
    from pkmcal.identification.uncertainty import _inverse_normal, embed

    poses = mechanism.as_pose_array(poses)
    method = default_method(setup, mechanism) if method is None else method
    rep = identifiability(mechanism, setup, poses, method=method) if report is None else report
    J, ok, names = design_jacobian(mechanism, setup.sensor, setup.noise, poses, method)
    free = [names.index(n) for n in rep.names if n not in rep.fixed]
    rows = J[ok][:, :, free].reshape(-1, len(free))
    cov = embed(_inverse_normal(rows), np.asarray(free), len(names))
    n = len(mechanism.params) + len(setup.sensor.params)
    return cov[:n, :n]


#: Grid points per axis of the predicted-accuracy map over the workspace box.
MAP_GRID = 7


@dataclass(frozen=True)
class AccuracyMap:
    """The predicted accuracy (:class:`PredictedAccuracy`) at the reachable points of a
    ``MAP_GRID``³ grid of the workspace box's x, y, z (the other coordinates at home), and
    at P1…P5 of the ISO 9283 cube (``cube``); ``covariance`` says which covariance."""

    grid: PredictedAccuracy
    cube: PredictedAccuracy
    covariance: str

    def to_dict(self) -> dict:
        def block(p: PredictedAccuracy) -> dict:
            out = {"position_95_mm": p.position.tolist()}
            if p.orientation is not None:
                out["orientation_95_deg"] = np.rad2deg(p.orientation).tolist()
            return out

        g = self.grid
        worst = int(np.argmax(g.position))
        return {"level": g.level, "covariance": self.covariance, "points": int(len(g.poses)),
                "position_95_mm": {"median": float(np.median(g.position)), "max": float(g.position[worst]),
                                   "max_at_mm": g.poses[worst, :3].tolist()},
                "orientation_95_deg": None if g.orientation is None else {
                    "median": float(np.rad2deg(np.median(g.orientation))),
                    "max": float(np.rad2deg(np.max(g.orientation)))},
                "iso9283_cube": {"poses_mm": self.cube.poses[:, :3].tolist(), **block(self.cube)}}

    def lines(self) -> list[str]:
        from pkmcal.conventions import angle_text, length_text

        g = self.grid
        worst = int(np.argmax(g.position))
        out = [f"predicted accuracy after calibrating on these poses ({100 * g.level:g} % bound of the position error "
               f"over {len(g.poses)} reachable points of the workspace at the home orientation; {self.covariance}): "
               f"median {length_text(float(np.median(g.position)))}, at most {length_text(float(g.position[worst]))} "
               f"(at x {g.poses[worst, 0]:.4g}, y {g.poses[worst, 1]:.4g}, z {g.poses[worst, 2]:.4g} mm)"]
        if g.orientation is not None:
            out.append(f"  orientation: median {angle_text(float(np.median(g.orientation)))}, at most "
                       f"{angle_text(float(np.max(g.orientation)))}")
        out.append("  expected ISO 9283 AP_P at the cube's P1..P5: " + ", ".join(
            f"P{i + 1} <= {length_text(v)}" for i, v in enumerate(self.cube.position)))
        return out


def accuracy_map(mechanism: Mechanism, setup, poses: np.ndarray, *, covariance: np.ndarray | None = None,
                 level: float = 0.95, margin=None, method: str | None = None, report=None) -> AccuracyMap:
    """The accuracy a calibration on ``poses`` with ``setup`` predicts over the workspace,
    before anything is measured (module docstring): :func:`plan_covariance` (or a given
    ``covariance`` (p, p), e.g. a calibrated file's) carried to the reachable points of a
    grid of the planning workspace box and to the ISO 9283 cube's P1…P5."""
    from pkmcal.planning.candidates import check_candidates, workspace_box
    from pkmcal.planning.margins import planning_checks, resolve_margin

    _position_axes(mechanism)
    what = "the covariance given"
    if covariance is None:
        covariance = plan_covariance(mechanism, setup, poses, method, report)
        what = "noise-model covariance (J^T W J)^-1 of these poses, gauge as identifiability suggests"
    reachable, _ = mechanism.within_geometry()
    checked, check_margin = planning_checks(reachable, resolve_margin(reachable) if margin is None else margin)
    box = workspace_box(checked, setup, margin=check_margin)
    axes = [np.linspace(lo, hi, MAP_GRID) for lo, hi in box[:3]]
    pts = np.tile(np.asarray(mechanism.home_pose, dtype=float), (MAP_GRID ** 3, 1))
    pts[:, :3] = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    pts = pts[check_candidates(checked, setup, pts, margin=check_margin).ok]
    if not len(pts):
        raise PkmcalError(f"no point of the workspace grid of '{mechanism.name}' passes its limits at the home "
                          "orientation: no accuracy map")
    cube = iso9283_pattern(mechanism, setup, margin=margin)
    sensor = setup.sensor if len(covariance) > len(mechanism.params) else None
    return AccuracyMap(predicted_accuracy(mechanism, covariance, pts, level, sensor),
                       predicted_accuracy(mechanism, covariance, cube.poses, level, sensor), what)


# -- from a verification ------------------------------------------------------------------------


def _pattern_or_reason(mechanism: Mechanism, poses: np.ndarray):
    """:func:`detect_pattern`'s ``(label, P1…P5)``; None when the poses are not five poses
    in cycles at all; why not (a sentence) when five poses repeat but do not make the
    pattern (a row left out, a pose moved): what a user who ran the pattern needs to know."""
    found = detect_pattern(mechanism, poses)
    if not isinstance(found, str):
        return found
    if found.startswith("not five") or "distinct poses" in found:
        return None
    return f"the held-out poses are five poses in cycles but not the ISO 9283 pattern: {found}"


def verification_figures(report, mechanism: Mechanism, poses: np.ndarray, *,
                         machine_covariance: np.ndarray | None = None, identified: dict | None = None
                         ) -> Iso9283Report | str | None:
    """The ISO 9283 figures of a held-out verification against a simulated true machine
    (:func:`pkmcal.identification.verification.verify`) whose held-out ``poses`` (as given,
    N × n) follow the pattern (:func:`detect_pattern`): the reached poses against the
    commanded ones (after the alignment with ``compare="aligned"``), exact (no instrument:
    U = 0); with ``machine_covariance`` the AP_P each pose was predicted to have (not when
    ``identified``, the calibrated file's ``setup:``, says sensor parameters were estimated:
    :func:`_without_prediction`). None when the poses are not five poses in cycles; why not
    (one sentence) when they look like the pattern but the figures cannot be computed."""
    found = _pattern_or_reason(mechanism, mechanism.as_pose_array(poses))
    if found is None or isinstance(found, str):
        return found
    label, commanded = found
    after = report.after
    if report.compare not in ("commanded", "aligned") or after.commanded is None:
        return (f"ISO 9283 figures compare platform poses (--compare commanded or aligned); this verification "
                f"compares '{report.compare}'")
    if not after.valid.all():
        return f"the real machine does not reach {int(np.count_nonzero(~after.valid))} of the pattern's poses"
    e = pose_errors(mechanism, after.reached, after.commanded)
    predicted = None
    machine_covariance, notes = _without_prediction(machine_covariance, identified)
    if machine_covariance is not None:
        predicted = predicted_accuracy(mechanism, machine_covariance, commanded).position
    return iso9283_figures(arrange(label, e), commanded, predicted_mm=predicted, notes=notes,
                           uncertainty=f"none: the true machine is simulated and its poses are exact, no instrument "
                                       f"(U = 0); compared as {report.compare}")


def _without_prediction(machine_covariance, identified: dict | None) -> tuple[np.ndarray | None, tuple[str, ...]]:
    """``(machine_covariance, ())``, or ``(None, (why,))`` when the calibrated file's
    ``setup:`` block ``identified`` has estimated sensor parameters (``std``): the file keeps
    no covariance between them and the machine, and the machine's block alone describes the
    platform frame the gauge chose, not the tool point (module docstring)."""
    std = (identified or {}).get("std") or {}
    if not std or machine_covariance is None:
        return machine_covariance, ()
    return None, (f"no predicted AP_P: the calibration also estimated {', '.join(std)}, and the calibrated file "
                  "keeps no covariance between them and the machine, which the tool point's accuracy needs "
                  "('pkmcal identifiability --accuracy' predicts it for a plan)",)


def heldout_figures(mechanism: Mechanism, setup, measurements, *, identified: dict | None = None,
                    machine_covariance: np.ndarray | None = None) -> Iso9283Report | str | None:
    """The ISO 9283 figures of measured held-out data whose commanded poses (the file's
    ``cmd_*`` columns) follow the pattern: :func:`measured_report` with the instrument of
    ``setup`` (its identified sensor) and the registration's covariance from ``identified``,
    the calibrated file's ``setup:`` block: its ``std`` (mm, degrees) of the sensor's
    parameters, as a diagonal covariance (the file keeps no correlations between them), and
    its ``covariance_kind``. None when the commanded poses are not five poses in cycles (or
    not in the file); why not when they look like the pattern but the figures cannot be
    computed (:func:`_pattern_or_reason`, an instrument that reads neither pose nor point)."""
    if measurements.commanded is None:
        return None
    found = _pattern_or_reason(mechanism, measurements.commanded)
    if found is None or isinstance(found, str):
        return found
    label, _ = found
    if _tool_point(mechanism, setup.sensor) is None:
        return (f"the held-out poses follow the ISO 9283 pattern, but the '{setup.sensor.kind}' instrument reads "
                "neither the pose nor a point of the platform")
    cov, note = None, ""
    std = (identified or {}).get("std") or {}
    registered = [n for n in std if n in REGISTRATION]
    if registered:
        names = list(setup.sensor.param_names)
        angle = dict(zip(names, setup.sensor.param_is_angle))
        cov = np.zeros((len(names), len(names)))
        for name in registered:
            k = names.index(name)
            cov[k, k] = float(np.deg2rad(std[name]) if angle[name] else std[name]) ** 2
        note = (f"the calibration's std of {', '.join(registered)} as a diagonal covariance: "
                f"{(identified or {}).get('covariance_kind') or 'identified'}")
    machine_covariance, notes = _without_prediction(machine_covariance, identified)
    rep = measured_report(mechanism, setup, measurements.readings, measurements.commanded, label, sensor_cov=cov,
                          covariance_note=note, machine_covariance=machine_covariance)
    return dataclasses.replace(rep, notes=rep.notes + tuple(notes))
