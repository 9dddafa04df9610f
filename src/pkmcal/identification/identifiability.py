"""Identifiability: which parameter combinations a machine + setup + pose set can determine.

The identification Jacobian J (rows: the noise-whitened residuals of every pose, as the
engine fits them; columns: the candidate parameters) is analysed as follows.

* **Scaling.** Columns are scaled to unit Euclidean norm, J_s = J D, D = diag(1/‖J_:,i‖),
  so that the rank and the singular values do not depend on the parameters' units (mm,
  rad). A column that is identically zero is a parameter the data do not see at all.
* **Rank.** Singular values σ_1 ≥ … of J_s (computed as those of R in J_s = QR when J_s
  is tall); rank = #{σ_i > rtol·σ_1} with
  ``rtol = 1e-8`` (exact gauge freedoms give σ/σ_1 ~ 1e-15; a genuine but weak parameter
  on realistic pose sets is above 1e-6). Directions with rtol < σ_i/σ_1 < ``weak_ratio``
  (1e-4, i.e. noise amplified more than 10⁴ times relative to the best direction) are
  reported as *weakly identifiable*.
* **Null space** in physical units: δθ = D V_null. It is a subspace; we write it in the
  basis tied to the suggested gauge G (one direction per fixed parameter g, with
  coefficient +1 on g and 0 on the other fixed parameters): N_G = N (N[G])⁻¹. Each
  direction says "raise g by 1 (mm or rad) and move these parameters by these amounts, and
  no reading changes". Coefficients below 1e-6 of the largest are dropped.
* **Gauge** (a minimal set of parameters to fix so that the rest is identifiable): chosen
  greedily in an order of preference, keeping the fixed set well conditioned (a parameter
  is fixed only if its row of the null-space basis, projected off the rows already chosen,
  has at least 1 % of the largest row norm). Preference (documented, paper 2 §2.2): fix
  the joints that *define the frames* first: mechanism parameters in the order of
  ``Mechanism.param_names`` (for the hexapod: b1, a1, then b2, a2, ... — paper 2 fixes b1,
  b2, a1, a2), leg offsets (``L0_*``) after all joints, sensor parameters last (they
  describe the measuring set-up, which the calibration should determine).
* **Named directions** (issue 13, item 5): a machine declares directions its users know by
  name (:meth:`~pkmcal.mechanisms.base.Mechanism.named_directions`: a delta's common scale
  of arms and radius). A direction d (all of whose parameters are candidates) is judged
  modulo the gauge: in scaled coordinates u = D⁻¹d/‖D⁻¹d‖, its part u' = u − N Nᵀu off the
  null space N of J_s (a gauge change is not a change of d), and with W an orthonormal
  basis of u'⊥ (every other direction, the gauge included, free to compensate), the
  visibility v = ‖(I − P_{J_s W}) J_s u‖ (P the projector onto the range of J_s W). The
  direction's amount is its coordinate in the unit-norm columns, ε = dᵀD⁻²θ/‖D⁻¹d‖² (the
  amount of a direction depends on what counts as "the rest"; this choice is free of the
  parameters' units). On the noise-whitened J, σ = 1/(v ‖D⁻¹d‖) is the standard deviation
  of ε that the measurements leave (linearised at the nominal machine). It is *unidentifiable*
  when u' = 0 or v/σ_1 is at most ``rtol``; *weak* below
  ``weak_ratio``; *not determined* when σ exceeds the tolerance the machine declares for it
  (a genuine but noise-swamped direction); else *identified*. After a fit,
  :func:`undetermined_directions` judges them on every parameter the machine does not hold
  (what the data can see, not what one fit freed), with the fit's priors as rows, and says
  which of the direction's parameters the fit held (issue 25: what ``identify`` and
  ``export`` print), each flagged ``note`` (said, not warned: a placement direction, where a
  delta's tower set stands on the bed) or not, and for a touch probe on a bed what would
  determine the rail leans (:func:`pkmcal.identification.advice.plane_held_advice`).
"""

from __future__ import annotations

import dataclasses
import re
from fnmatch import fnmatchcase
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np


RANK_RTOL = 1e-8
WEAK_RATIO = 1e-4
_DROP = 1e-6
_WEAK_DROP = 0.05


@dataclass(frozen=True)
class IdentifiabilityReport:
    """What a pose set and sensor can identify (module docstring).

    ``names`` the candidate parameters; ``singular_values`` of the column-scaled Jacobian
    (descending); ``rank``; ``null_space`` one {name: coefficient} per unidentifiable
    direction (physical units, gauge basis); ``fixed`` the suggested gauge; ``weak`` one
    {"ratio": σ/σ_1, "direction": {name: coefficient}} per weakly identifiable direction;
    ``unseen`` parameters whose Jacobian column is zero.
    """

    names: tuple[str, ...]
    singular_values: np.ndarray
    rank: int
    null_space: list[dict[str, float]]
    fixed: tuple[str, ...]
    weak: list[dict] = field(default_factory=list)
    unseen: tuple[str, ...] = ()
    rtol: float = RANK_RTOL
    n_rows: int = 0
    #: What the Jacobian was evaluated on (method and poses), e.g. "fk-residual at 40 planned
    #: poses (noise-free, nominal machine)".
    basis: str = ""
    #: Poses left out because their readings or nuisance pose could not be computed.
    n_unsolved: int = 0
    #: The candidate parameters that are angles (rad here; degrees in :meth:`to_dict`).
    angle_names: tuple[str, ...] = ()
    #: One dict per named direction of the machine (module docstring): ``meaning``,
    #: ``status``, ``ratio``, ``sigma`` (of the amount, in ``unit``), ``tolerance``,
    #: ``tolerance_why``, ``remedy``, ``direction``.
    named: list = field(default_factory=list)

    @property
    def n_params(self) -> int:
        return len(self.names)

    @property
    def identifiable(self) -> bool:
        return self.rank == self.n_params

    @property
    def condition_number(self) -> float:
        s = self.singular_values
        return float(s[0] / s[self.rank - 1]) if self.rank > 0 else float("inf")

    def _file_direction(self, d: dict[str, float], unit_on: str | None) -> dict[str, float]:
        """A direction {name: coefficient} with its angle parameters in degrees: each
        coefficient times 180/π for an angle parameter, divided by the same factor of
        ``unit_on`` (the parameter whose coefficient is 1), else renormalised to max 1."""
        f = {n: (180.0 / np.pi if n in self.angle_names else 1.0) for n in d}
        out = {n: c * f[n] for n, c in d.items()}
        norm = f[unit_on] if unit_on in out else max((abs(v) for v in out.values()), default=1.0) or 1.0
        return {n: float(v / norm) for n, v in out.items()}

    def to_dict(self) -> dict:
        """JSON-ready; angle parameters in degrees (directions in file units, mm and deg)."""
        gauge_of = [next((n for n in self.fixed if d.get(n) == 1.0), None) for d in self.null_space]
        return {
            "n_params": self.n_params,
            "n_rows": self.n_rows,
            "rank": self.rank,
            "rank_rtol": self.rtol,
            "column_scaling": "unit norm",
            "condition_number": self.condition_number,
            "singular_values": [float(s) for s in self.singular_values],
            "null_space": [self._file_direction(d, g) for d, g in zip(self.null_space, gauge_of)],
            "fixed": list(self.fixed),
            "weak": [{"ratio": float(w["ratio"]), "direction": self._file_direction(w["direction"], None)}
                     for w in self.weak],
            "unseen": list(self.unseen),
            "parameters": list(self.names),
            "basis": self.basis,
            "n_unsolved_poses": self.n_unsolved,
            "named": [{k: (v if k != "sigma" or np.isfinite(v) else None) for k, v in d.items()} for d in self.named],
            "units": {"n_params": "1", "n_rows": "1", "rank": "1", "rank_rtol": "1", "condition_number": "1",
                      "singular_values": "1 (of the column-scaled, whitened Jacobian)",
                      "null_space": "coefficients of each direction in file units (mm; deg for angle "
                                    "parameters), 1 on the gauge parameter it is named after",
                      "weak": "ratio: 1 (sigma/sigma_1); direction: coefficients in file units (mm, deg), "
                              "largest 1",
                      "n_unsolved_poses": "1",
                      "named": "sigma and tolerance in each entry's unit (1: relative); ratio: 1; direction: "
                               "internal units (mm, rad) per unit amount; sigma null when unidentifiable"},
        }

    def describe(self, limit: int = 3) -> str:
        """One-line human summary of the unidentifiable combinations."""
        if self.identifiable:
            return f"all {self.n_params} parameters identifiable (rank {self.rank})"
        parts = [format_direction(d) for d in self.null_space[:limit]]
        more = "" if len(self.null_space) <= limit else f" and {len(self.null_space) - limit} more"
        return (f"rank {self.rank} of {self.n_params}: unobservable combinations {'; '.join(parts)}{more}; "
                f"fix e.g. {', '.join(self.fixed)}")


def describe_named(entry: dict) -> str:
    """One line of a named direction's verdict, e.g. "a common scale of the arm lengths and
    the radius: not determined by these measurements (sigma 1.8 % ...); add ..."."""
    unit, sigma = entry["unit"], entry["sigma"]

    def amount(v):
        return f"{100 * v:.2g} %" if unit == "1" else f"{v:.3g} {unit}"

    if entry["status"] == "unidentifiable":
        return f"{entry['meaning']}: cannot be seen by these measurements (no reading changes along it: sigma " \
               f"unbounded, tolerance {amount(entry['tolerance'])}); {entry['remedy']}"
    text = (f"sigma {amount(sigma)} with this setup's noise, tolerance {amount(entry['tolerance'])} "
            f"({entry['tolerance_why']}); ratio {entry['ratio']:.2g}")
    if entry["status"] == "identified":
        return f"{entry['meaning']}: identified ({text})"
    words = {"weak": "weakly seen by these measurements", "not determined": "not determined by these measurements"}
    return f"{entry['meaning']}: {words[entry['status']]} ({text}); {entry['remedy']}"


def named_directions_report(J: np.ndarray, names, directions, *, rtol: float = RANK_RTOL,
                            weak_ratio: float = WEAK_RATIO) -> list[dict]:
    """The verdict on each named direction (module docstring) of the whitened candidate
    Jacobian ``J`` (M, P) of parameters ``names``; directions with a parameter that is not
    a candidate are left out (they cannot move)."""
    from scipy.linalg import null_space

    names = list(names)
    J = np.asarray(J, dtype=float)
    col = np.linalg.norm(J, axis=0)
    scale = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
    Js = J * scale
    if not Js.size:
        return []
    _, sv_all, Vt = np.linalg.svd(Js, full_matrices=True)
    smax = float(sv_all[0]) if sv_all.size else 0.0
    rank = int(np.sum(sv_all > rtol * smax)) if smax > 0 else 0
    N = Vt[rank:].T                                        # null space of J_s (P, d)
    out = []
    for nd in directions:
        if not nd.direction or not all(n in names for n in nd.direction) or not smax > 0:
            continue
        d = np.zeros(len(names))
        for n, c in nd.direction.items():
            d[names.index(n)] = c
        ds = d / scale                                     # the direction in scaled coordinates
        size = np.linalg.norm(ds)
        u = ds / size
        u_off = u - N @ (N.T @ u)                          # the part that is not a gauge change
        if np.linalg.norm(u_off) > rtol:
            A = Js @ null_space(u_off[None, :])            # every other direction, the gauge too, free
            U, sv, _ = np.linalg.svd(A, full_matrices=False)
            U = U[:, sv > rtol * smax]
            b = Js @ u
            v = float(np.linalg.norm(b - U @ (U.T @ b)))
        else:
            v = 0.0
        ratio = v / smax
        sigma = float("inf") if ratio <= rtol else 1.0 / (size * v)
        status = ("unidentifiable" if ratio <= rtol else "weak" if ratio < weak_ratio
                  else "not determined" if sigma > nd.tolerance else "identified")
        out.append({"meaning": nd.meaning, "status": status, "ratio": ratio, "sigma": sigma, "unit": nd.unit,
                    "tolerance": nd.tolerance, "tolerance_why": nd.tolerance_why, "remedy": nd.remedy,
                    "direction": dict(nd.direction), "placement": nd.placement})
    return out


def format_direction(direction: dict[str, float], digits: int = 3) -> str:
    """``{'b1.x': 1, 'b2.x': -0.5}`` → ``"b1.x − 0.5·b2.x"``."""
    out = []
    for i, (name, c) in enumerate(direction.items()):
        sign = "-" if c < 0 else "+"
        mag = abs(c)
        term = name if abs(mag - 1.0) < 10 ** (-digits) else f"{mag:.{digits}g}*{name}"
        out.append((("-" if sign == "-" else "") if i == 0 else f" {sign} ") + term)
    return "".join(out)


@lru_cache(maxsize=64)
def _fix_priority(names: tuple[str, ...], mechanism_names: tuple[str, ...]) -> tuple[int, ...]:
    """Indices of ``names`` in the order they are preferred for fixing (module docstring);
    memoised, as a fit asks for the same parameter set again and again."""
    mech = set(mechanism_names)
    order = {n: i for i, n in enumerate(mechanism_names)}

    def key(i: int):
        n = names[i]
        if n not in mech:
            return (2, i)
        if re.match(r"L0_", n):
            return (1, order[n])
        m = re.search(r"(\d+)", n)
        leg = int(m.group(1)) if m else 0
        return (0, leg, order[n])

    return tuple(sorted(range(len(names)), key=key))


def choose_gauge(null: np.ndarray, priority: list[int]) -> list[int]:
    """Rows of the null-space basis ``null`` (P, d) to fix, greedily in ``priority`` order."""
    d = null.shape[1]
    if d == 0:
        return []
    norms = np.linalg.norm(null, axis=1)
    chosen: list[int] = []
    basis = np.zeros((0, d))            # orthonormal basis of the chosen rows' span (Gram–Schmidt)
    for thresh in (1e-2, 1e-8):
        for i in priority:
            if len(chosen) == d:
                break
            if i in chosen:
                continue
            row = null[i] - basis.T @ (basis @ null[i])
            size = np.linalg.norm(row)
            if size > thresh * norms.max():
                chosen.append(i)
                row = row - basis.T @ (basis @ row)     # second pass: orthogonal to rounding
                basis = np.vstack([basis, row / np.linalg.norm(row)])
    return chosen


def _clean(vec: np.ndarray, names, drop: float) -> dict[str, float]:
    mag = np.abs(vec)
    big = mag.max() if vec.size else 0.0
    if not big > 0:
        return {}
    return {names[i]: float(vec[i]) for i in np.flatnonzero(mag > drop * big)}


class ScaledJacobian:
    """An identification Jacobian J (M, P) with unit-norm columns, J_s = J D, factored once
    (J_s = Q R) for both the cheap full-rank certificate and the full analysis."""

    def __init__(self, J: np.ndarray):
        from pkmcal.identification._small_linalg import qr_triangle  # compiled: numba on first use

        self.J = np.asarray(J, dtype=float)
        M, P = self.J.shape
        self.col = np.linalg.norm(self.J, axis=0)
        self.scale = np.where(self.col > 0, 1.0 / np.where(self.col > 0, self.col, 1.0), 1.0)
        Js = self.J * self.scale
        # the P×P triangle of J_s = Q R has J_s's singular values and right singular vectors;
        # its SVD is cheaper than that of the tall J_s (backward stable either way)
        self.R = qr_triangle(Js) if M > P else Js

    def certainly_full_rank(self, rtol: float = RANK_RTOL) -> bool:
        """True only if J has rank P in the sense of :meth:`analyse` (σ_P > rtol·σ_1),
        proven without an SVD (:meth:`condition_bound` · rtol < 1).

        False means "run the full analysis", not "rank deficient". The triangular inverse
        costs ~0.02 ms for P = 42, the SVD of R ~0.4 ms (2-core Xeon, 2026-11-22), which is
        why :func:`~pkmcal.identification.engine.identify` asks this first.
        """
        kappa = self.condition_bound()
        return bool(np.isfinite(kappa) and kappa * rtol < 1.0)

    def condition_bound(self) -> float:
        """An upper bound of the 2-norm condition number σ_1/σ_P of J_s, without an SVD
        (inf when none is proven: fewer rows than columns, a zero column or pivot).

        σ_1 ≤ ‖R‖_F and σ_P = 1/‖R⁻¹‖_2 ≥ 1/‖R⁻¹‖_F, so σ_1/σ_P ≤ ‖R‖_F ‖R⁻¹‖_F, within a
        factor P of the condition number. Computed once and kept: the engine asks it
        against two thresholds (rank, weak directions).
        """
        kappa = getattr(self, "_kappa", None)
        if kappa is None:
            kappa = self._kappa = self._condition_bound()
        return kappa

    def _condition_bound(self) -> float:
        M, P = self.J.shape
        if M < P or P == 0 or not np.all(self.col > 0) or not np.all(np.diag(self.R) != 0):
            return float("inf")
        from scipy.linalg.lapack import dtrtri

        Rinv, info = dtrtri(self.R, lower=0)
        if info != 0:
            return float("inf")
        kappa = float(np.linalg.norm(self.R) * np.linalg.norm(Rinv))
        return kappa if np.isfinite(kappa) else float("inf")

    def analyse(self, names, mechanism_names=(), *, rtol: float = RANK_RTOL,
                weak_ratio: float = WEAK_RATIO) -> IdentifiabilityReport:
        """The full report (see :func:`analyse_jacobian`)."""
        names = tuple(names)
        P = self.J.shape[1]
        scale = self.scale
        unseen = tuple(names[i] for i in np.flatnonzero(self.col == 0.0))
        _, s, Vt = np.linalg.svd(self.R, full_matrices=self.R.shape[0] < P)
        s_full = np.zeros(P)
        s_full[: s.size] = s
        smax = s_full[0] if P else 0.0
        rank = int(np.sum(s_full > rtol * smax)) if smax > 0 else 0
        V_null = Vt[rank:].T                                   # (P, d) scaled coordinates
        N = V_null * scale[:, None]                            # physical directions
        gauge = choose_gauge(N / np.linalg.norm(N, axis=0, keepdims=True) if N.size else N,
                             _fix_priority(names, tuple(mechanism_names)))
        null_space = []
        if gauge:
            NG = N @ np.linalg.inv(N[gauge])
            NG[np.abs(NG) < 1e-12 * np.abs(NG).max()] = 0.0
            NG[gauge] = np.eye(len(gauge))
            null_space = [_clean(NG[:, k], names, _DROP) for k in range(len(gauge))]
        weak = []
        for k in range(rank):
            ratio = s_full[k] / smax
            if ratio < weak_ratio:
                v = Vt[k] * scale
                v = v / np.max(np.abs(v))
                if v[np.argmax(np.abs(v))] < 0:
                    v = -v
                weak.append({"ratio": float(ratio), "direction": _clean(v, names, _WEAK_DROP)})
        return IdentifiabilityReport(
            names=names,
            singular_values=s_full,
            rank=rank,
            null_space=null_space,
            fixed=tuple(names[i] for i in gauge),
            weak=weak,
            unseen=unseen,
            rtol=rtol,
            n_rows=self.J.shape[0],
        )


def analyse_jacobian(
    J: np.ndarray,
    names: tuple[str, ...],
    mechanism_names: tuple[str, ...] = (),
    *,
    rtol: float = RANK_RTOL,
    weak_ratio: float = WEAK_RATIO,
) -> IdentifiabilityReport:
    """Rank, null space, weak directions and a suggested gauge of an identification Jacobian.

    ``J`` (M, P): rows the (whitened) residuals of all poses, columns the parameters
    ``names``; ``mechanism_names`` orders the gauge preference (module docstring).
    """
    return ScaledJacobian(J).analyse(names, mechanism_names, rtol=rtol, weak_ratio=weak_ratio)


def design_jacobian(machine, sensor, noise, poses: np.ndarray, method: str, weighted: bool = True,
                    form: str = "plain", sensor_columns: bool = True,
                    sessions=None) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """The engine's whitened residual Jacobian W_j J_j (N, k, P) of all parameters for
    noise-free readings simulated at ``poses`` (N, n) on the nominal machine (q = IK(x),
    y = h(x)), a flag (N,) of the poses whose nuisance pose was solved, and the parameter
    names: the identification Jacobian of a pose *plan*, which ``pkmcal identifiability``
    analyses and ``pkmcal identify`` judges its free set on when the measurements carry
    their commanded poses (same method, same weights, same candidate parameters).
    ``sensor_columns=False`` skips the sensor parameters' columns (NaN), as the engine does
    when none of them is a candidate. ``sessions``: the session of every pose
    (:class:`~pkmcal.sensors.sessions.Sessions`), with ``sensor`` a session sensor."""
    from pkmcal.identification.residuals import Model, make_method, whitening

    poses = machine.as_pose_array(poses)
    with np.errstate(invalid="ignore"):
        # the plain ik-residual's Jacobian and covariance do not depend on q (only its
        # residual q − IK does, which is not returned): no IK pass for readings unused
        q = np.zeros((len(poses), machine.n_actuators)) if method == "ik-residual" and form == "plain" \
            else machine.ik(poses)
        if sessions is not None:
            from pkmcal.sensors.sessions import bind_sessions

            sensor = bind_sessions(sensor, sessions)
        model = Model(machine, sensor, noise, q, sensor.predict(machine.frame(poses)), poses, sessions)
    meth = make_method(method, model, weighted, form=form)
    meth.sensor_columns = sensor_columns
    whiten = weighted and not meth.prewhitened            # the weighted projection is already whitened
    ev = meth.evaluate(model.theta0, jac=True, cov=whiten)
    cols = slice(None) if sensor_columns else slice(0, model.n_mech)
    ok = np.asarray(ev.converged, dtype=bool) & np.all(np.isfinite(ev.J[:, :, cols]), axis=(1, 2))
    J = ev.J
    if whiten:
        J = np.full_like(ev.J, np.nan)
        if ok.any():
            J[ok] = whitening(ev.cov[ok], f"{method} residual") @ ev.J[ok]
    return J, ok, model.names


def identifiability(
    machine,
    setup,
    poses: np.ndarray,
    *,
    method: str | None = None,
    free=None,
    fix=None,
    weighted: bool = True,
) -> IdentifiabilityReport:
    """Identifiability of the parameters for ``machine`` + ``setup`` measured at ``poses``.

    The Jacobian is the engine's (same method, same noise whitening), evaluated at the
    nominal machine on noise-free readings simulated at ``poses`` (N, n) (internal units;
    :func:`design_jacobian`). ``method`` defaults to
    :func:`~pkmcal.identification.residuals.default_method`, the engine's own default;
    ``free`` / ``fix`` select the candidate parameters as in
    :func:`~pkmcal.identification.engine.identify` (an explicit ``fix`` list is removed
    from the candidates; ``"auto"`` or ``None`` keeps them, the report suggests the gauge).
    Poses whose readings or nuisance pose cannot be computed (IK outside the reach, FK not
    solved) are left out; the report counts them in ``n_unsolved``.
    """
    from pkmcal.identification.residuals import single_threaded_blas

    with single_threaded_blas():
        return _identifiability(machine, setup, poses, method=method, free=free, fix=fix, weighted=weighted)


def _identifiability(machine, setup, poses, *, method, free, fix, weighted) -> IdentifiabilityReport:
    from pkmcal.identification.residuals import Model, candidate_parameters, default_method

    poses = machine.as_pose_array(poses)
    if method is None:
        method = default_method(setup, machine)
    J, ok, names = design_jacobian(machine, setup.sensor, setup.noise, poses, method, weighted)
    with np.errstate(invalid="ignore"):
        model = Model(machine, setup.sensor, setup.noise, machine.ik(poses[:1]),
                      setup.sensor.predict(machine.frame(poses[:1])))
    cand, _ = candidate_parameters(model, free, None if fix == "auto" else fix)
    rows = J[ok].reshape(-1, J.shape[-1])[:, cand]
    if rows.shape[0] == 0:
        from pkmcal.errors import PkmcalError

        raise PkmcalError(f"none of the {len(poses)} poses can be evaluated on machine '{machine.name}' "
                          "(outside the reach of its chains, or the pose cannot be solved): no identifiability")
    cand_names = tuple(names[i] for i in cand)
    rep = analyse_jacobian(rows, cand_names, tuple(machine.param_names))
    named = named_directions_report(rows, cand_names, machine.named_directions()) if weighted else []
    angles = tuple(n for n, a in zip(names, tuple(machine.param_is_angle) + tuple(setup.sensor.param_is_angle)) if a)
    return dataclasses.replace(rep, basis=f"{method} at {int(ok.sum())} planned poses (noise-free, nominal machine)",
                               n_unsolved=int(np.count_nonzero(~ok)), angle_names=angles, named=named)


def undetermined_directions(machine, setup, poses, priors=(), held=(), method: str | None = None) -> list[dict]:
    """The machine's named directions (:meth:`~pkmcal.mechanisms.base.Mechanism.named_directions`)
    that ``setup`` at ``poses`` (N, n, the commanded ones) does not determine to their
    tolerance, with ``priors`` (:class:`~pkmcal.identification.priors.Prior` or strings) as
    measurements too (a prior row pins its direction, :meth:`ResolvedPriors.augment`):
    :func:`named_directions_report` on the noise-whitened design Jacobian of every parameter
    the machine does not hold, whether or not the fit freed it (what the data can see, not
    what one fit chose). Each entry gets ``held``: the direction's parameters in ``held``
    (the fit's fixed ones: they stayed at the machine file's values) and ``text``, the plain
    line (:func:`describe_named` and what the fit did). Issue 25 item 2: ``identify`` and
    ``export`` print them, the exported file carries them."""
    from pkmcal.identification.priors import resolve
    from pkmcal.identification.residuals import Model, candidate_parameters, default_method, single_threaded_blas

    poses = machine.as_pose_array(poses)
    if method is None:
        method = default_method(setup, machine)
    directions = machine.named_directions()
    if not directions or not len(poses):
        return []
    with single_threaded_blas():
        J, ok, names = design_jacobian(machine, setup.sensor, setup.noise, poses, method, True)
        if not ok.any():
            return []
        with np.errstate(invalid="ignore"):
            model = Model(machine, setup.sensor, setup.noise, machine.ik(poses[:1]),
                          setup.sensor.predict(machine.frame(poses[:1])))
        cand, _ = candidate_parameters(model, None, None)
        rows = J[ok].reshape(-1, J.shape[-1])[:, cand]
        rp = resolve(tuple(getattr(setup, "priors", ()) or ()) + tuple(priors or ()), model.names,
                     model.param_is_angle, model.theta0)
        rows, _ = rp.augment(rows, cand, "")
        cand_names = tuple(names[i] for i in cand)
        named = named_directions_report(rows, cand_names, directions)
        from pkmcal.identification.advice import plane_held_advice

        rods_given = any(fnmatchcase(n, pat) for n in rp.names for pat in machine.held_without_length)
        lean = plane_held_advice(machine, setup, rows, cand_names, poses[ok], method, held, rods_given)
    out = []
    for e in named:
        if e["status"] == "identified":
            continue
        e = dict(e, held=[n for n in e["direction"] if n in set(held)])
        text = describe_named(e)
        others = [names[i] for i in cand if names[i] in set(held) and names[i] not in e["direction"]]
        if others and not e["placement"]:
            text += (f" (judged with the {len(others)} parameter(s) this fit held, {', '.join(others[:3])}"
                     f"{', ...' if len(others) > 3 else ''}, free too: what the data alone can tell)")
        if e["held"]:
            text += (f"; this fit held {', '.join(e['held'])} at the machine file's values, so the result is as right "
                     "along it as those values are")
        e["text"] = text
        e["note"] = e["placement"]
        out.append(e)
    if lean is not None and lean["status"] != "identified":
        out.append(lean)
    return out
