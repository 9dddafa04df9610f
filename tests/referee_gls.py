"""An independent referee for pkmcal's estimator: a textbook generalised-least-squares fit of a
Gough–Stewart hexapod written here with NumPy and SciPy alone (issue 24, item 2).

Nothing of pkmcal is imported: the referee reads the same files a user hands to ``pkmcal
identify`` — the machine file (``kind: hexapod``), the setup file and the measurement CSV —
with PyYAML and the ``csv`` module, and computes everything itself from the file formats of
docs/file-formats.md:

* **kinematics** (docs/conventions.md): pose x = (x, y, z, a, b, c), R = Rz(c)·Ry(b)·Rx(a);
  leg i joins the base joint b_i to the platform joint a_i, v_i = p + R a_i − b_i,
  L_i = |v_i| = L0_i + g_i λ_i, so the reading is λ_i = (L_i − L0_i)/g_i (inverse kinematics);
  forward kinematics by Newton's method on the six pose coordinates, λ(x, ρ) = q;
* **derivatives**, derived here: with u_i = v_i/L_i,
  ∂λ_i/∂p = u_iᵀ/g_i, ∂λ_i/∂(a, b, c) = u_iᵀ (∂R/∂angle) a_i / g_i, ∂λ_i/∂b_i = −u_iᵀ/g_i,
  ∂λ_i/∂a_i = (Rᵀu_i)ᵀ/g_i, ∂λ_i/∂L0_i = −1/g_i, ∂λ_i/∂g_i = −(L_i − L0_i)/g_i²;
  the sensors' derivatives by central differences of their closed forms
  (:func:`central_jacobian`); ``tests/identification/test_referee_ik_residual.py`` checks the analytic ones
  against the same differences;
* **sensors** (their models written from their definitions, docs/file-formats.md):
  full pose y = (p_w + R_w (p + R t), euler(R_w R R_t)); position (a tracker on one target)
  y = p_w + R_w (p + R t); dial indicators on a plate {W} at (p_W, R_W): indicator k at
  (x_k, y_k) of the plate, along z_W, touches the platform's lower plane (normal n = R e_z,
  through p − d n, d = ``plane_offset``) where n'·(X − x0') = 0 in plate coordinates,
  z_k = (n'·p' − d − n'_x x_k − n'_y y_k)/n'_z, and reads z_k − ζ_k;
* **the fit**, per measured pose j a residual r_j(θ) and its covariance Σ_j (first order):
  ``ik-residual`` (the pose x̂_j read by a full-pose sensor): r_j = q_j − λ(x̂_j, ρ),
  Σ_j = Σ_q + A D Σ_y Dᵀ Aᵀ (A = ∂λ/∂x, D = ∂x̂/∂y); ``fk-residual`` (x_j = FK(q_j, ρ)):
  r_j = y_j − h(x_j, s), Σ_j = Σ_y + H A⁻¹ Σ_q A⁻ᵀ Hᵀ (H = ∂h/∂x) and, by the implicit
  function theorem, ∂r_j/∂ρ = H A⁻¹ ∂λ/∂ρ. The GLS estimate minimises Σ_j |W_j r_j(θ)|² with
  W_j = chol(Σ_j)⁻¹ evaluated once at the starting values (the objective pkmcal documents:
  the weights are a constant of the fit), solved by ``scipy.optimize.least_squares`` to
  tolerances far below pkmcal's; the covariance is (J_wᵀ J_w)⁻¹ (J_w = W ∂r/∂θ) with the
  weights recomputed at the solution (the Gauss–Markov covariance, pkmcal's "a-priori"),
  from an SVD (:func:`covariance_of`).

Noise: standard deviations (``distribution: uniform``: half-widths h, σ = h/√3); the
full-pose orientation as ``orientation_deg`` (or ``orientation`` in radians).

What the referee does not model it refuses (:class:`NotModelled`): other machine kinds,
priors, several sessions, quaternion or rotation-vector columns, sensors other than these
three. A fit is general in the machine, the poses, the sensor's placement and which sensor
parameters are free (the setup's ``free:``, as pkmcal reads it), so any campaign of these
three sensors on any hexapod can be refereed: :func:`referee` (three files, a method, the
parameters to hold) → :class:`Fit`.

Below the referee, apart: what compares it with pkmcal's answer (:func:`assert_agree`, its
tolerances derived from pkmcal's stopping rule and the referee's differences), the Monte
Carlo statistics (:func:`trials_needed` derives the number of campaigns), and the few lines
that drive pkmcal to make a campaign's files and fit them (``run_pkmcal``, ``identify``,
``identify_api``, ``simulate_reached``), which import pkmcal inside themselves; the referee's
fit never calls them (``tests/identification/test_referee_ik_residual.py`` fits a campaign in a process
where pkmcal cannot be imported).
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field

import numpy as np
import yaml
from scipy.optimize import least_squares

POSE = ("x", "y", "z", "a", "b", "c")
LENGTH_TO_MM = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "um": 1e-3, "in": 25.4, "inch": 25.4}


class NotModelled(Exception):
    """The campaign uses something the referee does not model (so it cannot referee it)."""


# -- rotations ---------------------------------------------------------------------------------

def _axis_rotation(t, axis: int, derivative: bool = False) -> np.ndarray:
    """Rotation by t (...,) about coordinate axis ``axis`` (0 x, 1 y, 2 z), (..., 3, 3), or its
    derivative in t."""
    t = np.asarray(t, dtype=float)
    c, s = np.cos(t), np.sin(t)
    i, j = [(1, 2), (2, 0), (0, 1)][axis]        # the plane turned: e_i → c e_i + s e_j
    out = np.zeros(t.shape + (3, 3))
    if derivative:
        c, s = -s, c
    else:
        out[..., axis, axis] = 1.0
    out[..., i, i] = c
    out[..., j, j] = c
    out[..., j, i] = s
    out[..., i, j] = -s
    return out


def rotation(angles) -> np.ndarray:
    """R = Rz(c)·Ry(b)·Rx(a) of angles (..., 3) in radians, (..., 3, 3)."""
    angles = np.asarray(angles, dtype=float)
    return _axis_rotation(angles[..., 2], 2) @ _axis_rotation(angles[..., 1], 1) @ _axis_rotation(angles[..., 0], 0)


def rotation_derivatives(angles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """∂R/∂a, ∂R/∂b, ∂R/∂c (each (..., 3, 3)) of :func:`rotation`."""
    Rx, Ry, Rz = (_axis_rotation(angles[..., k], k) for k in range(3))
    dRx, dRy, dRz = (_axis_rotation(angles[..., k], k, derivative=True) for k in range(3))
    return Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx


def euler(R) -> np.ndarray:
    """(a, b, c) of R = Rz(c)·Ry(b)·Rx(a), b in [−π/2, π/2] (..., 3)."""
    b = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    return np.stack([np.arctan2(R[..., 2, 1], R[..., 2, 2]), b, np.arctan2(R[..., 1, 0], R[..., 0, 0])], -1)


def wrap(angle):
    """An angle difference brought into (−π, π]."""
    return -np.remainder(-angle + np.pi, 2 * np.pi) + np.pi


def central_jacobian(f, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """∂f/∂x by central differences for a batch: f maps (N, n) → (N, m); x (N, n) or (n,)
    (then shared by the batch); returns (N, m, n). Step h_k per coordinate: the truncation
    error h²/6·f''' and the rounding error ε|f|/h of these smooth closed forms (|f| ≲ 10³ mm,
    f''' ≲ 1 per mm² or rad³) are both ≲ 1e-9 relative for h = 1e-4 mm and 1e-5 rad."""
    x = np.asarray(x, dtype=float)
    cols = []
    for k, h in enumerate(steps):
        xp, xm = x.copy(), x.copy()
        xp[..., k] += h
        xm[..., k] -= h
        cols.append((f(xp) - f(xm)) / (2 * h))
    return np.stack(cols, -1)


def _steps(is_angle) -> np.ndarray:
    return np.where(np.asarray(is_angle, dtype=bool), 1e-5, 1e-4)


POSE_STEPS = _steps([False] * 3 + [True] * 3)


# -- files -------------------------------------------------------------------------------------

def _read_yaml(path) -> dict:
    with open(path, encoding="utf-8") as f:
        data = yaml.load(f, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    if not isinstance(data, dict):
        raise NotModelled(f"{path}: not a YAML mapping")
    return data


def _transform(d, keys=POSE) -> np.ndarray:
    """A transform mapping {x, y, z, a, b, c} (mm, degrees; missing keys 0) → (mm, rad)."""
    d = d or {}
    out = np.array([float(d.get(k, 0.0)) for k in keys])
    if len(keys) == 6:
        out[3:] = np.deg2rad(out[3:])
    return out


@dataclass
class Hexapod:
    """A hexapod read from a machine file: ρ = per leg (b_i, a_i, L0_i), then the gains."""

    params: np.ndarray
    home: np.ndarray | None
    stroke: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:
        out = []
        for i in range(1, 7):
            out += [f"b{i}.{c}" for c in "xyz"] + [f"a{i}.{c}" for c in "xyz"] + [f"L0_{i}"]
        return tuple(out) + tuple(f"gain_{i}" for i in range(1, 7))

    @property
    def is_angle(self) -> tuple[bool, ...]:
        return (False,) * 48


def read_hexapod(path) -> Hexapod:
    """The machine file ``path`` (a hexapod: ``legs`` with ``base``, ``platform``, ``offset``,
    ``gain``, ``stroke``; optional ``home`` in mm and degrees)."""
    d = _read_yaml(path)
    if d.get("kind", "hexapod") != "hexapod":
        raise NotModelled(f"{path}: kind {d.get('kind')!r}; the referee models hexapods only")
    legs = d["legs"]
    if len(legs) != 6:
        raise NotModelled(f"{path}: {len(legs)} legs")
    geo = [list(map(float, leg["base"])) + list(map(float, leg["platform"])) + [float(leg["offset"])] for leg in legs]
    gains = [float(leg.get("gain", 1.0)) for leg in legs]
    home = None if "home" not in d else _transform(d["home"])
    stroke = np.array([[float(v) for v in leg["stroke"]] for leg in legs])
    return Hexapod(np.array(sum(geo, []) + gains), home, stroke)


def legs_of(rho: np.ndarray):
    """(B (6, 3), A (6, 3), L0 (6,), g (6,)) of ρ."""
    geo = rho[:42].reshape(6, 7)
    return geo[:, 0:3], geo[:, 3:6], geo[:, 6], rho[42:48]


def inverse_kinematics(x: np.ndarray, rho: np.ndarray, derivatives: bool = False):
    """Readings λ (N, 6) of poses x (N, 6) (module docstring); with ``derivatives`` also
    A = ∂λ/∂x (N, 6, 6) and ∂λ/∂ρ (N, 6, 48)."""
    B, Ap, L0, g = legs_of(rho)
    R = rotation(x[:, 3:6])
    RA = np.einsum("nij,kj->nki", R, Ap)                        # R a_i (N, 6, 3)
    v = x[:, None, 0:3] + RA - B
    L = np.linalg.norm(v, axis=-1)
    lam = (L - L0) / g
    if not derivatives:
        return lam
    u = v / L[..., None]
    N = x.shape[0]
    A = np.empty((N, 6, 6))
    A[..., 0:3] = u / g[:, None]
    for m, dR in enumerate(rotation_derivatives(x[:, 3:6])):
        A[..., 3 + m] = np.einsum("nki,nij,kj->nk", u, dR, Ap) / g
    Bm = np.zeros((N, 6, 48))
    Rtu = np.einsum("nji,nkj->nki", R, u)                       # Rᵀ u_i
    for i in range(6):
        Bm[:, i, 7 * i:7 * i + 3] = -u[:, i] / g[i]
        Bm[:, i, 7 * i + 3:7 * i + 6] = Rtu[:, i] / g[i]
        Bm[:, i, 7 * i + 6] = -1.0 / g[i]
        Bm[:, i, 42 + i] = -(L[:, i] - L0[i]) / g[i] ** 2
    return lam, A, Bm


def forward_kinematics(q: np.ndarray, rho: np.ndarray, start: np.ndarray, tol: float = 1e-12,
                       max_iter: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Poses x (N, 6) with λ(x, ρ) = q by Newton's method from ``start`` (N, 6); returns
    (x, converged). Converged: the readings match to 1e-9 mm and the last step was below
    ``tol`` (mm, rad) — well inside the noise, and exact enough that the fit's finite
    differences of the pose are not spoiled."""
    x = np.array(start, dtype=float)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            lam, A, _ = inverse_kinematics(x, rho, derivatives=True)
            bad = ~(np.all(np.isfinite(A), axis=(1, 2)) & np.all(np.isfinite(lam), axis=1))
            if bad.any():                     # a diverged pose stays put (and is reported)
                A[bad], lam[bad] = np.eye(6), q[bad]
            try:
                step = np.linalg.solve(A, (lam - q)[..., None])[..., 0]
            except np.linalg.LinAlgError:     # a singular pose: least squares, pose by pose
                step = np.stack([np.linalg.lstsq(a, d, rcond=None)[0] for a, d in zip(A, lam - q)])
            x -= step
            if np.all(np.max(np.abs(step), axis=1) < tol):
                break
        res = np.max(np.abs(inverse_kinematics(x, rho) - q), axis=1)
    return x, (res < 1e-9) & np.all(np.isfinite(x), axis=1)


# -- sensors -----------------------------------------------------------------------------------

@dataclass
class Sensor:
    """One of the three sensor models (module docstring): ``kind``, parameter ``names`` with
    their ``values`` s (mm, rad) and angle flags, reading names, what a setup frees."""

    kind: str
    names: tuple[str, ...]
    values: np.ndarray
    is_angle: tuple[bool, ...]
    readings: tuple[str, ...]
    reading_is_angle: tuple[bool, ...]
    free: tuple[str, ...]
    positions: np.ndarray | None = None      # indicators (K, 2)
    plane_offset: float = 0.0

    def predict(self, x: np.ndarray, s: np.ndarray, R: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, m) of poses x (N, 6) at sensor parameters s (R: the poses' rotations,
        when known)."""
        p, R = x[:, 0:3], rotation(x[:, 3:6]) if R is None else R
        if self.kind == "full-pose":
            pw, Rw, pt, Rt = s[0:3], rotation(s[3:6]), s[6:9], rotation(s[9:12])
            pos = pw + (p + R @ pt) @ Rw.T
            return np.concatenate([pos, euler(Rw @ R @ Rt)], axis=1)
        if self.kind == "position":
            t, pw, Rw = s[0:3], s[3:6], rotation(s[6:9])
            return pw + (p + R @ t) @ Rw.T
        k = len(self.positions)                                    # indicators
        zero, pW, RW = s[0:k], s[k:k + 3], rotation(s[k + 3:k + 6])
        pp = (p - pW) @ RW                                         # p' = R_Wᵀ (p − p_W)
        n = (R[:, :, 2]) @ RW                                      # n' = R_Wᵀ R e_z
        top = np.einsum("ni,ni->n", n, pp)[:, None] - self.plane_offset - n[:, 0:2] @ self.positions.T
        return top / n[:, 2:3] - zero

    def difference(self, y: np.ndarray, h: np.ndarray) -> np.ndarray:
        """y − h, angles wrapped into (−π, π]."""
        d = y - h
        ang = np.asarray(self.reading_is_angle, dtype=bool)
        d[:, ang] = wrap(d[:, ang])
        return d

    def pose_of(self, y: np.ndarray, s: np.ndarray) -> np.ndarray:
        """The platform pose x̂ (N, 6) a full-pose sensor's readings y determine (closed form:
        R = R_wᵀ R_T R_tᵀ, p = R_wᵀ (y_pos − p_w) − R t)."""
        if self.kind != "full-pose":
            raise NotModelled(f"the ik-residual needs a full-pose sensor, not {self.kind}")
        pw, Rw, pt, Rt = s[0:3], rotation(s[3:6]), s[6:9], rotation(s[9:12])
        R = Rw.T @ rotation(y[:, 3:6]) @ Rt.T
        p = (y[:, 0:3] - pw) @ Rw - R @ pt
        return np.concatenate([p, euler(R)], axis=1)


def _values(v, n: int) -> np.ndarray:
    a = np.asarray(v if isinstance(v, list) else [v] * n, dtype=float)
    if a.shape != (n,):
        raise NotModelled(f"a noise list of {a.size} values for {n} readings")
    return a


@dataclass
class Setup:
    sensor: Sensor
    sigma_y: np.ndarray
    sigma_q: np.ndarray


def read_setup(path) -> Setup:
    """The setup file ``path`` (``sensor:`` full-pose, position or indicators)."""
    d = _read_yaml(path)
    for key in ("prior", "sessions"):
        if key in d:
            raise NotModelled(f"{path}: '{key}:' is not modelled by the referee")
    kind = d.get("sensor")
    free = d.get("free")
    if kind == "full-pose":
        names = tuple(f"world.{c}" for c in POSE) + tuple(f"tool.{c}" for c in POSE)
        values = np.concatenate([_transform(d.get("world")), _transform(d.get("tool"))])
        ang = (False,) * 3 + (True,) * 3
        sensor = Sensor(kind, names, values, ang * 2, POSE, ang, tuple(free or ()))
    elif kind == "position":
        names = tuple(f"target.{c}" for c in "xyz") + tuple(f"world.{c}" for c in POSE)
        values = np.concatenate([_transform(d.get("target"), "xyz"), _transform(d.get("world"))])
        sensor = Sensor(kind, names, values, (False,) * 6 + (True,) * 3, ("px", "py", "pz"), (False,) * 3,
                        tuple(free) if free is not None else names[0:3])   # the target is free unless told
    elif kind == "indicators":
        pos = np.array(d["indicators"], dtype=float)
        k = len(pos)
        names = tuple(f"zero{i + 1}" for i in range(k)) + tuple(f"plate.{c}" for c in POSE)
        values = np.concatenate([np.asarray(d.get("zero", [0.0] * k), dtype=float), _transform(d.get("plate"))])
        sensor = Sensor(kind, names, values, (False,) * (k + 3) + (True,) * 3, tuple(f"d{i + 1}" for i in range(k)),
                        (False,) * k, tuple(free or ()), positions=pos, plane_offset=float(d.get("plane_offset", 0.0)))
    else:
        raise NotModelled(f"{path}: sensor {kind!r} is not modelled by the referee")
    noise = d["noise"]
    scale = 1.0 / math.sqrt(3.0) if noise.get("distribution", "gaussian") == "uniform" else 1.0
    m = len(sensor.readings)
    if kind == "full-pose":
        ori = np.deg2rad(_values(noise["orientation_deg"], 3)) if "orientation_deg" in noise else \
            _values(noise["orientation"], 3)
        sigma_y = np.concatenate([_values(noise["position"], 3), ori])
    else:
        sigma_y = _values(noise["reading"], m)
    return Setup(sensor, sigma_y * scale, _values(noise["actuator"], 6) * scale)


@dataclass
class Measurements:
    q: np.ndarray               # (N, 6) actuator readings
    y: np.ndarray               # (N, m) sensor readings, mm and rad
    commanded: np.ndarray | None


def read_measurements(path, machine: Hexapod, sensor: Sensor) -> Measurements:
    """A measurement CSV: a header, ``#`` comment lines (a ``# units: length=…, angle=…`` line
    converts), ``lambda1..6`` or leg lengths ``l1..6``, the sensor's columns, optionally
    ``cmd_x..cmd_c``."""
    length, angle = 1.0, math.pi / 180.0
    rows, header = [], None
    with open(path, encoding="utf-8-sig", newline="") as f:
        for row in csv.reader(f):
            if not row or not "".join(row).strip():
                continue
            if header is None and row[0].lstrip().startswith("#"):
                text = ",".join(row)
                if "units:" in text:
                    for item in text.split("units:", 1)[1].split(","):
                        k, _, v = item.strip().partition("=")
                        if k == "length":
                            length = LENGTH_TO_MM[v.strip()]
                        elif k == "angle":
                            angle = {"deg": math.pi / 180.0, "rad": 1.0}[v.strip()]
                continue
            if header is None:
                header = [h.strip().lower() for h in row]
                continue
            rows.append(row)
    cols = {h: i for i, h in enumerate(header)}
    if "session" in cols and len({r[cols["session"]].strip() for r in rows}) > 1:
        raise NotModelled(f"{path}: several sessions are not modelled by the referee")

    def col(name, scale):
        if name not in cols:
            raise NotModelled(f"{path}: no column '{name}' (quaternions and rotation vectors are not read)")
        return np.array([float(r[cols[name]]) for r in rows]) * scale

    if all(f"lambda{i}" in cols for i in range(1, 7)):
        q = np.column_stack([col(f"lambda{i}", 1.0) for i in range(1, 7)])
    else:
        _, _, L0, g = legs_of(machine.params)
        q = (np.column_stack([col(f"l{i}", length) for i in range(1, 7)]) - L0) / g
    y = np.column_stack([col(n, angle if a else length) for n, a in zip(sensor.readings, sensor.reading_is_angle)])
    cmd = None
    if all(f"cmd_{c}" in cols for c in POSE):
        cmd = np.column_stack([col(f"cmd_{c}", angle if k >= 3 else length) for k, c in enumerate(POSE)])
    return Measurements(q, y, cmd)


# -- the fit -----------------------------------------------------------------------------------

def default_home(machine: Hexapod) -> np.ndarray:
    """A start pose for FK when the file gives neither commanded poses nor ``home``: level and
    centred, at the height where the legs' mean length is mid-stroke (any start in the
    basin of Newton's method does; the fit checks that every pose converges)."""
    B, A, L0, g = legs_of(machine.params)
    target = L0 + g * machine.stroke.mean(axis=1)
    d = A - B
    # |(0, 0, z) + d_i|² = target_i², least squares in z for the mean over the legs
    zs = -d[:, 2] + np.sqrt(np.maximum(target**2 - d[:, 0] ** 2 - d[:, 1] ** 2, 0.0))
    return np.array([0.0, 0.0, float(np.mean(zs)), 0.0, 0.0, 0.0])


@dataclass
class Fit:
    """The referee's estimate: every parameter (``names``, ``theta`` in mm and rad), the free
    ones, their covariance (J_wᵀJ_w)⁻¹ with the weights at the solution (``jw`` = J_w there),
    χ², the cost ½|W r|² and the whitened residual at the solution (with the start weights)."""

    names: tuple[str, ...]
    theta: np.ndarray
    free: tuple[str, ...]
    covariance: np.ndarray
    chi2: float
    cost: float
    residual: np.ndarray
    jw: np.ndarray = field(repr=False, default=None)

    def value(self, name: str) -> float:
        return float(self.theta[self.names.index(name)])

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))


class Referee:
    """The GLS fit of one campaign (machine, setup, measurements; module docstring).

    ``method``: ``ik-residual`` or ``fk-residual``; ``free``: the names of the estimated
    parameters (default: the 42 joint positions and leg offsets, not the gains, and the
    setup's free sensor parameters — what ``pkmcal identify`` frees by default), less
    ``fixed`` (a gauge)."""

    def __init__(self, machine: Hexapod, setup: Setup, meas: Measurements, method: str,
                 free=None, fixed=(), weighted: bool = True):
        if method not in ("ik-residual", "fk-residual"):
            raise NotModelled(f"method {method!r}")
        self.machine, self.setup, self.meas, self.method = machine, setup, meas, method
        self.sensor = setup.sensor
        self.names = machine.names + self.sensor.names
        self.is_angle = machine.is_angle + self.sensor.is_angle
        self.theta0 = np.concatenate([machine.params, self.sensor.values])
        if free is None:
            free = machine.names[:42] + self.sensor.free
        unknown = set(free) - set(self.names)
        if unknown:
            raise NotModelled(f"unknown parameters {sorted(unknown)}")
        self.free = tuple(n for n in self.names if n in set(free) and n not in set(fixed))
        self.idx = np.array([self.names.index(n) for n in self.free])
        self.weighted = weighted
        N = len(meas.q)
        if meas.commanded is not None:
            self.start = meas.commanded.copy()
        else:
            home = machine.home if machine.home is not None else default_home(machine)
            self.start = np.tile(home, (N, 1))
        self._x = self.start.copy()
        _, _, cov = self.evaluate(self.theta0, jac=False, cov=True)
        self.W = np.linalg.inv(np.linalg.cholesky(cov)) if weighted else np.broadcast_to(np.eye(cov.shape[1]), cov.shape)

    # residual, Jacobian (all free columns), covariance of one θ
    def evaluate(self, theta, jac: bool = True, cov: bool = False):
        rho, s = theta[:48], theta[48:]
        sens, meas = self.sensor, self.meas
        free_s = bool(np.any(self.idx >= 48))
        if self.method == "ik-residual":
            xhat = sens.pose_of(meas.y, s)
            lam, A, B = inverse_kinematics(xhat, rho, derivatives=True)
            r = meas.q - lam
            J = C = None
            if jac:
                J = np.zeros(r.shape + (len(theta),))
                J[..., :48] = -B
                if free_s:
                    J[..., 48:] = -A @ self._ds(lambda ss: sens.pose_of(meas.y, ss), s)
            if cov:
                Dy = central_jacobian(lambda yy: sens.pose_of(yy, s), meas.y, _steps(sens.reading_is_angle))
                M = A @ Dy
                C = np.diag(self.setup.sigma_q**2) + (M * self.setup.sigma_y**2) @ np.swapaxes(M, 1, 2)
            return r, J, C
        x, ok = forward_kinematics(meas.q, rho, self._x)
        if not ok.all():
            x2, ok2 = forward_kinematics(meas.q, rho, self.start)
            x = np.where(ok2[:, None], x2, x)
            ok = ok2
        if not ok.all():
            return None, None, None
        self._x = x
        h = sens.predict(x, s)
        r = sens.difference(meas.y, h)
        J = C = None
        if jac or cov:
            _, A, B = inverse_kinematics(x, rho, derivatives=True)
            H = central_jacobian(lambda xx: sens.predict(xx, s), x, POSE_STEPS)
            HAi = np.swapaxes(np.linalg.solve(np.swapaxes(A, 1, 2), np.swapaxes(H, 1, 2)), 1, 2)   # H A⁻¹
            if jac:
                J = np.zeros(r.shape + (len(theta),))
                J[..., :48] = HAi @ B
                if free_s:
                    R = rotation(x[:, 3:6])
                    J[..., 48:] = -self._ds(lambda ss: sens.predict(x, ss, R), s)
            if cov:
                C = np.diag(self.setup.sigma_y**2) + (HAi * self.setup.sigma_q**2) @ np.swapaxes(HAi, 1, 2)
        return r, J, C

    def _ds(self, f, s):
        """∂f/∂s (N, k, |s|) by central differences in the free sensor parameters (the
        columns of held ones are 0)."""
        out = None
        for k in self.idx[self.idx >= 48] - 48:
            h = 1e-5 if self.sensor.is_angle[k] else 1e-4
            sp, sm = s.copy(), s.copy()
            sp[k] += h
            sm[k] -= h
            d = (f(sp) - f(sm)) / (2 * h)
            if out is None:
                out = np.zeros(d.shape + (len(s),))
            out[..., k] = d
        return out

    def theta(self, z) -> np.ndarray:
        th = self.theta0.copy()
        th[self.idx] = z
        return th

    def whitened(self, z) -> np.ndarray:
        r, _, _ = self.evaluate(self.theta(z), jac=False)
        if r is None:
            return np.full(self.W.shape[0] * self.W.shape[1], 1e10)
        return (self.W @ r[..., None])[..., 0].ravel()

    def whitened_jacobian(self, z) -> np.ndarray:
        _, J, _ = self.evaluate(self.theta(z), jac=True)
        Jw = self.W @ J[..., self.idx]
        return Jw.reshape(-1, len(self.idx))

    def rank(self, names=None, rtol: float = 1e-8) -> tuple[int, np.ndarray]:
        """Rank of the whitened Jacobian at the start over ``names`` (default the free ones),
        columns scaled to unit norm, and its singular values relative to the largest."""
        names = self.free if names is None else tuple(names)
        cols = [self.names.index(n) for n in names]
        keep = self.idx
        self.idx = np.array(cols)
        try:
            J = self.whitened_jacobian(self.theta0[self.idx])
        finally:
            self.idx = keep
        J = J / np.linalg.norm(J, axis=0)
        sv = np.linalg.svd(J, compute_uv=False)
        sv = sv / sv[0]
        return int(np.sum(sv > rtol)), sv

    def whitened_jacobian_at(self, theta) -> np.ndarray:
        """J_w (M, p) of the free parameters at θ, whitened with the weights at θ itself (the
        information J_wᵀJ_w there; what a covariance at a solution is made of)."""
        _, J, C = self.evaluate(theta, jac=True, cov=True)
        return (np.linalg.inv(np.linalg.cholesky(C)) @ J[..., self.idx]).reshape(-1, len(self.idx))

    def fit(self, tol: float = 1e-15, start=None) -> Fit:
        """Minimise Σ|W_j r_j|² (Levenberg–Marquardt, MINPACK through scipy, Jacobian scaling)
        from the files' values, or from θ = ``start`` (the weights stay those of the files)."""
        z0 = (self.theta0 if start is None else np.asarray(start, dtype=float))[self.idx]
        sol = least_squares(self.whitened, z0, jac=self.whitened_jacobian, method="lm", x_scale="jac",
                            ftol=tol, xtol=tol, gtol=tol, max_nfev=200 * (len(z0) + 1))
        theta = self.theta(sol.x)
        r, _, C = self.evaluate(theta, jac=False, cov=True)
        rw_end = (np.linalg.inv(np.linalg.cholesky(C)) @ r[..., None])[..., 0].ravel()
        Jw = self.whitened_jacobian_at(theta)
        rw = self.whitened(sol.x)
        return Fit(self.names, theta, self.free, covariance_of(Jw), float(rw_end @ rw_end), 0.5 * float(rw @ rw), rw, Jw)


def covariance_of(Jw: np.ndarray) -> np.ndarray:
    """(J_wᵀJ_w)⁻¹ from the SVD of the column-scaled J_w: forming and inverting J_wᵀJ_w squares
    the condition number (4e8 on paper 1's corners), which costs ~1e-3 of the weakest
    directions' variances; the SVD keeps the error at ε·κ."""
    d = np.linalg.norm(Jw, axis=0)
    _, s, Vt = np.linalg.svd(Jw / d, full_matrices=False)
    V = Vt.T / s
    return (V @ V.T) / np.outer(d, d)


def condition_number(Jw: np.ndarray) -> float:
    """κ of the column-scaled J_w."""
    s = np.linalg.svd(Jw / np.linalg.norm(Jw, axis=0), compute_uv=False)
    return float(s[0] / s[-1])


def covariance_deviation(Jw: np.ndarray, cov: np.ndarray) -> tuple[float, float]:
    """Extreme eigenvalues of C·J_wᵀJ_w (1 and 1 when ``cov`` is the inverse information of
    J_w), as squared singular values of J_w·L (C = L Lᵀ, both scaled by √diag C): no
    ill-conditioned inverse is formed."""
    d = np.sqrt(np.diag(cov))
    s = np.linalg.svd((Jw * d) @ np.linalg.cholesky(cov / np.outer(d, d)), compute_uv=False)
    return float(s[-1] ** 2), float(s[0] ** 2)


def referee(machine_file, setup_file, measurement_file, method: str, *, free=None, fixed=(), weighted=True,
            y=None, start=None) -> tuple[Referee, Fit]:
    """Fit the campaign of these three files (``y``: other sensor readings in place of the
    file's, e.g. noise-free ones; ``start``: θ to start from); returns the problem and its fit."""
    machine = read_hexapod(machine_file)
    setup = read_setup(setup_file)
    meas = read_measurements(measurement_file, machine, setup.sensor)
    if y is not None:
        meas = Measurements(meas.q, np.asarray(y, dtype=float), meas.commanded)
    ref = Referee(machine, setup, meas, method, free=free, fixed=fixed, weighted=weighted)
    return ref, ref.fit(start=start)


def truth_in_gauge(ref: Referee, fit: Fit, real_file, true_setup_file) -> np.ndarray:
    """The true machine and sensor (``real_file``, ``true_setup_file``) as the parameters held
    by ``ref`` see them (all parameters, mm and rad): the referee's fit of the truth's
    noise-free readings (:func:`exact_readings`) from ``fit``; its residual must vanish, else
    the held parameters were no gauge (an assertion)."""
    y = exact_readings(ref, real_file, true_setup_file)
    exact = Referee(ref.machine, ref.setup, Measurements(ref.meas.q, y, ref.meas.commanded), ref.method, free=ref.free)
    got = exact.fit(start=fit.theta, tol=1e-10)   # a zero-residual fit: stop once it is ~1e-10 σ
    r, _, _ = exact.evaluate(got.theta, jac=False)
    assert np.max(np.abs(r)) < 1e-7, f"the truth's exact readings are not fitted with {ref.free} free: {np.abs(r).max()}"
    return got.theta


def exact_readings(ref: Referee, machine_file, setup_file) -> np.ndarray:
    """The sensor readings (N, m) the machine of ``machine_file`` would give, read by the sensor
    of ``setup_file`` (its values), at ``ref``'s actuator readings, without noise: the data of
    a campaign's truth, to find the truth's representative in a gauge (fit them with the gauge
    held: zero residual, or the held parameters are no gauge)."""
    truth = read_hexapod(machine_file)
    sensor = read_setup(setup_file).sensor
    if sensor.kind != ref.sensor.kind or sensor.names != ref.sensor.names:
        raise NotModelled(f"{setup_file}: another sensor than the fit's")
    start = ref.start
    x, ok = forward_kinematics(ref.meas.q, truth.params, start)
    if not ok.all():
        raise NotModelled("the true machine's FK did not converge for every pose")
    return sensor.predict(x, sensor.values)


# -- comparing with pkmcal's answer, read from its files -----------------------------------------

def pkmcal_values(fit_json: dict, names, key: str = "estimate") -> np.ndarray:
    """``key`` (``estimate``, ``std_prior``, ...) of the parameters ``names`` in ``pkmcal
    identify --json`` (file units: degrees for angle parameters), in mm and rad."""
    return np.array([math.radians(p[key]) if p["unit"] == "deg" else p[key]
                     for p in (fit_json["parameters"][n] for n in names)])


def file_covariance(machine_file) -> tuple[tuple[str, ...], np.ndarray]:
    """(names, covariance) of a calibrated machine file's ``uncertainty:`` block."""
    u = _read_yaml(machine_file)["uncertainty"]
    return tuple(u["parameters"]), np.array(u["covariance"], dtype=float)


def convergence_tolerance(cost: float, ftol: float = 1e-10) -> float:
    """How far (in σ of each parameter) two minimisers of the same objective may differ when
    one stops at a relative cost reduction ``ftol`` (pkmcal's ftol = xtol = gtol = 1e-10).

    Near the minimum the cost is quadratic: cost(θ) − cost* = ½ δᵀFδ (F = J_wᵀJ_w, the
    inverse covariance), and a stop on a relative reduction below ftol leaves
    ½ δᵀFδ ≲ ftol·cost, i.e. ‖δ‖_F ≤ sqrt(2·ftol·cost). By Cauchy–Schwarz every parameter
    obeys |δ_i| ≤ σ_i ‖δ‖_F (σ_i² = (F⁻¹)_ii), and the whitened fitted residuals differ by at
    most ‖δ‖_F. The referee's own tolerance (1e-15) and its central differences in the
    weights (1e-9 relative, which move the minimiser by ~1e-9 σ) add nothing visible; the
    factor 10 covers a stop on xtol instead (a step of 1e-10 relative) and a last step
    that did not land on the quadratic's minimum."""
    return 10.0 * math.sqrt(2.0 * ftol * max(cost, 1.0))


def covariance_tolerance(Jw: np.ndarray) -> float:
    """How far pkmcal's a-priori covariance C_P may differ from the inverse information of the
    referee's J_w at pkmcal's own estimate, as the relative deviation of any eigenvalue of
    C_P·J_wᵀJ_w from 1 (:func:`covariance_deviation`; every σ_i² ratio lies within them).

    Both are (J_wᵀJ_w)⁻¹ at the same point; the referee's J_w has the central-difference
    error of its sensor derivatives, ≤ 1e-9 relative per entry (:func:`central_jacobian`),
    so C_R^{-1/2} C_P C_R^{-1/2} = (I + E)⁻¹ with ‖E‖ ≤ 2‖δJ_w‖/σ_min(J_w) ≤ 2·1e-9·κ, κ
    the condition number of the column-scaled J_w. Safety factor 5: 1e-8·κ (2e-4 on paper
    1's corners, κ ≈ 2e4). (At the referee's own estimate, 1e-6 σ away, J_w moves by
    ~δθ/L ≈ 3e-8 and the weakest directions' variances by 1e-3: hence the common point.)"""
    return 1e-8 * condition_number(Jw)


def marginal_jacobian(Jw: np.ndarray, sel) -> np.ndarray:
    """The columns ``sel`` of J_w with the other columns' span projected out: its information
    is the marginal one, (J⊥ᵀJ⊥)⁻¹ = ((J_wᵀJ_w)⁻¹)[sel, sel] (the Schur complement)."""
    sel = list(sel)
    other = [i for i in range(Jw.shape[1]) if i not in sel]
    J = Jw[:, sel]
    if not other:
        return J
    Q, _ = np.linalg.qr(Jw[:, other])
    return J - Q @ (Q.T @ J)


def assert_agree(fit_json: dict, ref: Referee, fit: Fit, calibrated=None) -> float:
    """pkmcal's estimate equals the referee's parameter by parameter within the convergence
    tolerance (in σ), its fitted residuals too, and its a-priori σ the referee's; with the
    ``calibrated`` machine file pkmcal wrote, its covariance (over the machine's free
    parameters, divided by the recorded inflation max(1, χ²/E[χ²])) is the referee's as a
    matrix: every direction's variance within the covariance tolerance. Returns the largest
    difference in σ."""
    assert fit_json["success"], fit_json["message"]
    assert tuple(fit_json["free"]) == fit.free, "pkmcal frees other parameters than the referee"
    tol = convergence_tolerance(fit.cost)
    pk = pkmcal_values(fit_json, fit.free)
    mine = np.array([fit.value(n) for n in fit.free])
    z = np.abs(pk - mine) / fit.std
    worst = int(np.argmax(z))
    assert z[worst] <= tol, f"{fit.free[worst]}: pkmcal {pk[worst]!r}, referee {mine[worst]!r} ({z[worst]:.3g} σ > {tol:.3g})"
    # gauge-free: the referee's whitened residual at pkmcal's estimate (its sensor too)
    theta = fit.theta.copy()
    every = [n for n in fit_json["parameters"] if n in fit.names]
    theta[[fit.names.index(n) for n in every]] = pkmcal_values(fit_json, every)
    moved = np.linalg.norm(ref.whitened(theta[ref.idx]) - fit.residual)
    assert moved <= tol, f"fitted residuals differ by {moved:.3g} (whitened) > {tol:.3g}"
    # the covariance: the referee's information at pkmcal's estimate
    jw = ref.whitened_jacobian_at(theta)
    ctol = covariance_tolerance(jw)
    ratio = pkmcal_values(fit_json, fit.free, "std_prior") / np.sqrt(np.diag(covariance_of(jw)))
    assert np.max(np.abs(ratio - 1)) <= ctol, f"a-priori σ: pkmcal/referee within {ratio.min()}..{ratio.max()} (> {ctol:.3g})"
    if calibrated is not None:
        names, cov_file = file_covariance(calibrated)
        sel = [fit.free.index(n) for n in names]
        lo, hi = covariance_deviation(marginal_jacobian(jw, sel),
                                         cov_file / max(1.0, fit_json["birge_ratio"]))
        assert 1 - ctol <= lo and hi <= 1 + ctol, f"file covariance · referee information: eigenvalues {lo}..{hi}"
    return float(z[worst])


# -- the Monte Carlo checks ----------------------------------------------------------------------

#: Efficiency loss the Monte Carlo must detect (MSE ratio 1.1), and the ratio above which it fails.
LOSS, THRESHOLD = 0.10, 1.02
#: One-sided normal quantile of the detection: a 10 % loss passes with probability < 1e-3.
Z_DETECT = 3.09


def trials_needed(r: int, loss: float = LOSS, threshold: float = THRESHOLD, z: float = Z_DETECT) -> int:
    """Campaigns K that make a ``loss`` of efficiency fail the ratio test with probability
    ≥ Φ(z), for r identifiable directions.

    Statistic: the mean squared error in the metric of the information F = J_wᵀJ_w (each
    direction in units of its own σ, so gauge-free and dominated by no single weak
    direction), R̂ = Σ_k e_P,kᵀF_k e_P,k / Σ_k e_R,kᵀF_k e_R,k over K campaigns, pkmcal (P) and
    the referee (R) on the same files: paired, so the noise common to both cancels.
    Whitened, the referee's error e ~ N(0, I_r) (it is the Gauss–Markov estimator); any other
    linear unbiased estimator is e + d with d uncorrelated with e (Gauss–Markov), and a loss ℓ
    means E|d|² = ℓr. Per campaign D = |e + d|² − |e|² = 2e·d + |d|², E[D] = ℓr,
    Var D = 4 tr S + 2 tr S² ≤ 4ℓr + 2ℓ²r² (S = Cov d; tr S² ≤ (tr S)², the worst case the
    whole loss in one direction). R̂ > t fails when D̄ > (t − 1)·r (the denominator's mean is
    r with relative sd sqrt(2/(Kr)), negligible here), so with Δ = ℓ − (t − 1):

        P(detect) ≥ Φ(Δ r √K / sqrt(4ℓr + 2ℓ²r²))  ⇒  K ≥ z² (4ℓ/(Δ² r) + 2ℓ²/Δ²).

    ℓ = 0.1, t = 1.02, z = 3.09 (miss ≤ 1e-3): r = 42 → K = 45; r = 39 → K = 46. The correct
    estimator passes with certainty: pkmcal and the referee minimise the same objective, so
    e_P − e_R is the convergence difference (≤ 1e-3 σ, asserted per campaign) and
    |R̂ − 1| ≤ 2·1e-3/√r + 1e-6 ≪ 0.02."""
    delta = loss - (threshold - 1.0)
    return math.ceil(z**2 * (4 * loss / (delta**2 * r) + 2 * loss**2 / delta**2))


def efficiency_ratio(e_pkmcal: np.ndarray, e_referee: np.ndarray, jw: np.ndarray | None = None) -> float:
    """R̂ of :func:`trials_needed`: parameter errors (K, r) with whitened Jacobians (K, M, r),
    eᵀFe = |J_w e|²; or, ``jw`` None, whitened prediction errors (K, M) as they are."""
    if jw is not None:
        e_pkmcal, e_referee = np.einsum("kmi,ki->km", jw, e_pkmcal), np.einsum("kmi,ki->km", jw, e_referee)
    return float(np.sum(e_pkmcal**2) / np.sum(e_referee**2))


#: Probability with which a correct covariance fails a coverage check (any seed).
FALSE_FAILURE = 1e-6


def mahalanobis(e: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """d² = eᵀC⁻¹e per campaign: errors (K, r), covariances (K, r, r)."""
    return np.einsum("ki,ki->k", e, np.linalg.solve(cov, e[..., None])[..., 0])


def prediction_d2(jw: np.ndarray, cov: np.ndarray, delta: np.ndarray) -> float:
    """d² of a whitened prediction error Δ (M,) under the covariance ``cov`` of the parameters
    propagated to the predictions, J_w C J_wᵀ (rank r): |A⁺Δ|² with A = J_w L, C = L Lᵀ. For
    the GLS estimate Δ ≈ J_w e, e ~ N(0, (J_wᵀJ_w)⁻¹), so with the right C, d² ~ χ²_r; it
    is gauge-free and blind to how curved the parametrisation is (only the predictions
    count)."""
    d = np.sqrt(np.diag(cov))
    A = (jw * d) @ np.linalg.cholesky(cov / np.outer(d, d))
    c = np.linalg.lstsq(A, delta, rcond=None)[0]
    return float(c @ c)


@dataclass
class PredictionTrials:
    """The Monte Carlo of whitened prediction errors (Δ = W(h(θ̂) − h(θ*)): the fit's residual
    at θ̂ less that at the truth's representative in the gauge; gauge-free and blind to the
    parametrisation's curvature), pkmcal's and the referee's, with pkmcal's d² under its
    a-priori covariance (:func:`prediction_d2`), whether it is inside its file covariance's
    95 % ellipsoid, and its per-parameter errors in its file σ."""

    r: int
    pkmcal: list = field(default_factory=list)
    referee: list = field(default_factory=list)
    d2: list = field(default_factory=list)
    inside: list = field(default_factory=list)
    z: list = field(default_factory=list)

    def add(self, ref: Referee, fit: Fit, fit_json: dict, truth: np.ndarray) -> None:
        at_truth = ref.whitened(truth[ref.idx])
        theta = fit.theta.copy()
        theta[ref.idx] = pkmcal_values(fit_json, fit.free)
        self.pkmcal.append(ref.whitened(theta[ref.idx]) - at_truth)
        self.referee.append(fit.residual - at_truth)
        jw = ref.whitened_jacobian_at(theta)
        self.d2.append(prediction_d2(jw, fit_json["covariance_prior"], self.pkmcal[-1]))
        self.inside.append(prediction_d2(jw, fit_json["covariance"], self.pkmcal[-1]) <= stats_chi2_ppf(0.95, self.r))
        self.z.append((theta[ref.idx] - truth[ref.idx]) / np.sqrt(np.diag(fit_json["covariance"])))

    def check(self) -> str:
        """Assert the efficiency ratio (:func:`trials_needed`) and the coverage
        (:func:`coverage_bands`); returns the summary."""
        K = len(self.d2)
        ratio = efficiency_ratio(np.array(self.pkmcal), np.array(self.referee))
        (lo, hi), min_inside = coverage_bands(K, self.r)
        summary = (f"K={K}: MSE ratio pkmcal/referee {ratio:.6f}; mean d² {np.mean(self.d2):.2f} (band {lo:.2f}.."
                   f"{hi:.2f}); {sum(self.inside)} of {K} inside the 95 % ellipsoid (at least {min_inside}); "
                   f"per-parameter 95 % intervals hold {np.mean(np.abs(np.array(self.z)) <= 1.96):.3f} of the errors")
        assert abs(ratio - 1.0) <= THRESHOLD - 1.0, summary
        assert lo <= np.mean(self.d2) <= hi, summary
        assert sum(self.inside) >= min_inside, summary
        return summary


def prediction_monte_carlo(campaign, machine_file, setup_file, true_setup_file, r: int, first_seed: int) -> str:
    """:class:`PredictionTrials` over K = :func:`trials_needed` (r) campaigns ``campaign(seed)``
    → (measurement file, real machine file) or None (skipped), seeds from ``first_seed``:
    pkmcal's fk-residual fit (``pkmcal.identify`` on the files) and the referee's in pkmcal's
    gauge, equal per campaign (:func:`assert_agree`), errors against the truth's
    representative in that gauge (:func:`truth_in_gauge`, the sensor of ``true_setup_file``).
    Asserts the efficiency and the coverage; returns the summary."""
    trials = PredictionTrials(r=r)
    seed = first_seed
    while len(trials.d2) < trials_needed(r):
        made = campaign(seed)
        seed += 1
        if made is None:
            continue
        meas, real = made
        fit_json = identify_api(machine_file, meas, setup_file, method="fk-residual")
        ref, fit = referee(machine_file, setup_file, meas, "fk-residual", fixed=fit_json["gauge"])
        assert_agree(fit_json, ref, fit)
        trials.add(ref, fit, fit_json, truth_in_gauge(ref, fit, real, true_setup_file))
    return trials.check()


def coverage_bands(K: int, r: int, level: float = 0.95):
    """Under a correct covariance (errors Gaussian to first order): K·mean(d²) ~ χ²_{Kr}, and
    the count of campaigns inside the ``level`` ellipsoid ~ Binomial(K, level). Returns
    ((low, high) of mean d², lowest count inside), each failing a correct covariance with
    probability FALSE_FAILURE (two-sided for the mean, one-sided — too few inside, i.e. an
    over-confident σ — for the count)."""
    from scipy import stats

    lo, hi = stats.chi2.ppf([FALSE_FAILURE / 2, 1 - FALSE_FAILURE / 2], K * r) / K
    return (float(lo), float(hi)), int(stats.binom.ppf(FALSE_FAILURE, K, level))


# -- driving pkmcal: the campaign's files and pkmcal's answer (the referee above never calls this)

def run_pkmcal(*args) -> str:
    """``pkmcal ARGS`` through click's test runner (in-process, as a user would type it);
    its standard output. Any failure is an assertion naming the command and its output."""
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, f"pkmcal {' '.join(map(str, args))} -> {res.exit_code}: {res.output}"
    return res.stdout


def write_builtins(folder, machine: str = None, setup: str = None) -> tuple:
    """The files of a built-in machine and setup, as pkmcal saves them (the referee reads files)."""
    import pkmcal

    out = []
    if machine is not None:
        path = folder / f"{machine}.yaml"
        pkmcal.save_machine(pkmcal.load_machine(machine), path)
        out.append(path)
    if setup is not None:
        path = folder / f"{setup}.yaml"
        pkmcal.save_setup(pkmcal.load_setup(setup), path)
        out.append(path)
    return tuple(out)


def identify(machine_file, meas_file, setup_file, out_file, *options) -> dict:
    """``pkmcal identify MACHINE MEAS --setup SETUP -o OUT --json OPTIONS``: the fit as JSON."""
    import json

    return json.loads(run_pkmcal("identify", machine_file, meas_file, "--setup", setup_file, "-o", out_file,
                                 "--json", *options))


def simulate_reached(folder, machine_file, setup_file, poses_file, seed: int, n: int, errors_mm: float = 5.0):
    """A campaign: a real machine with every parameter off by U(−errors, errors) mm (``pkmcal
    simulate --random-errors``, seeded; the leg-collision check off, as paper 1's
    reproduction: the prototype's legs nearly touch), ``n`` of the poses it reaches (a seeded
    random choice). Returns (measurement file, real machine file), or None when it reaches
    fewer than ``n``."""
    every, meas, real = (folder / f"{name}-{seed}.{ext}" for name, ext in
                         (("reached", "csv"), ("meas", "csv"), ("real", "yaml")))
    run_pkmcal("simulate", machine_file, "--random-errors", errors_mm, "--save-real", real, "--setup", setup_file,
               "--poses", poses_file, "--seed", seed, "--ignore-limit", "leg_collision", "-o", every)
    reached = sum(1 for ln in open(every, encoding="utf-8") if ln.strip()) - 1
    if reached < n:
        return None
    keep_rows(every, meas, np.random.default_rng(seed).permutation(reached)[:n])
    return meas, real


def keep_rows(src, dst, rows) -> None:
    """The CSV ``src`` with only its data rows ``rows`` (0-based, in this order) as ``dst``,
    the header and the rows' text unchanged."""
    lines = [ln for ln in open(src, encoding="utf-8").read().splitlines() if ln and not ln.startswith("#")]
    with open(dst, "w", encoding="utf-8") as f:
        f.write("\n".join([lines[0]] + [lines[1 + i] for i in rows]) + "\n")


def stats_chi2_ppf(p: float, dof: int) -> float:
    """The χ² quantile (scipy.stats)."""
    from scipy import stats

    return float(stats.chi2.ppf(p, dof))


def identify_api(machine_file, meas_file, setup_file, **options) -> dict:
    """``pkmcal.identify`` on the same files, loaded by pkmcal's own readers (what the command
    does, without writing the calibrated file — its YAML is most of a command's time): the
    ``--json`` dictionary plus ``covariance_prior`` and ``covariance`` (the file's), over
    ``free``, mm and rad. The Monte Carlo uses this; the single-campaign tests the command."""
    import pkmcal

    machine = pkmcal.load_machine(machine_file)
    setup = pkmcal.load_setup(setup_file, machine)
    res = pkmcal.identify(machine, setup, pkmcal.load_measurements(meas_file, machine, setup), **options)
    out = res.to_dict()
    out["covariance_prior"] = np.array(res.uncertainty.covariance_prior)
    out["covariance"] = np.array(res.covariance)
    return out
