"""Which measurement to add: the available sensors and pose plans ranked by how much each
raises the rank and the smallest singular value of the identification Jacobian (issue 13,
item 5; ``pkmcal identifiability --suggest``).

The current campaign (machine, setup, poses) gives the whitened identification Jacobian J_0
of the candidate parameters θ (rows: the engine's noise-whitened residuals, as
:func:`~pkmcal.identification.identifiability.design_jacobian` computes them; the candidates
as :func:`~pkmcal.identification.identifiability.identifiability` selects them). An
*addition* k brings rows of its own, [J_k | S_k]: J_k on θ and S_k on the parameters of its
own sensor that its setup frees (a tracker's world transform), which the fit would estimate
too. Eliminating those (they are nuisances for θ) leaves the rows' information on θ,

    E_k = [J_0; (I − P_k) J_k],      P_k the orthogonal projector onto range(S_k)

(the Schur complement: E_kᵀE_k = J_0ᵀJ_0 + J_kᵀJ_k − J_kᵀS_k(S_kᵀS_k)⁺S_kᵀJ_k). An
addition of poses measured by the current setup shares its sensor parameters: E_k = [J_0;
J_k] over θ itself.

Every option is judged on the same scale and modulo the same gauge. With E_all the stack of
the current rows and every addition's, D = diag(1/‖E_all[:, i]‖) (unit-norm columns of the
union, one scaling for all options) and G an orthonormal basis of the null space of E_all D
(the *gauge*: what no available measurement sees, e.g. a delta's rotation about z under a Z
probe and printed distances; a gauge is fixed, not measured), each option is scored on
E_k D U, U an orthonormal basis of G⊥ (g = dim G):

* rank_k = #{σ_i > rtol · σ_1} of E_k D U, out of P − g;
* σ_min,k = the smallest of its P − g singular values, 0 below full rank (1/σ_min is the
  noise amplification of the worst-determined combination);
* σ_r,k the smallest singular value above the rank tolerance (the weakest combination it
  sees), and the gain σ_min,k / σ_min,0 (σ_r,k / σ_r,0 below full rank);
* the machine's named directions judged on E_k
  (:func:`~pkmcal.identification.identifiability.named_directions_report`, in the
  machine's words: "a common scale of the arm lengths and the radius: identified").

Options are ranked by rank, then σ_min, then how many named directions they identify, then
σ_r. The candidates: every built-in setup that can
measure the machine (:data:`~pkmcal.sensors.library.BUILTIN_SETUPS`), at the current poses
(where each reads there: a Z probe lowered onto the bed);
for a linear delta, Klipper's printed calibration object (12 distances between printed
points, :mod:`pkmcal.sensors.printed_distance` on :mod:`pkmcal.mechanisms.pose_pairs`); for a
touch probe on a machine that holds parameters on one plane, a gauge block probed at 13
places (:func:`block_poses`); and
as many poses again from each of the planners ``default`` and ``random``
(:func:`pkmcal.planning.plan.plan_poses`, fixed seed), taken where the sensor reads when sent
there (``Sensor.measured_frames``: a Z probe lowered onto the bed). A placement direction
(``NamedDirection.placement``: where a delta's tower set stands on the bed) that no option
sees is said once, not on every row.

What would determine the parameters a bed holds (issue 25 item 6;
:func:`plane_held_advice`, which ``identify`` and ``export`` print as a note): a delta's rail
leans, each one's σ from the covariance on the seen directions of the whitened rows with
unit-norm columns (:func:`parameter_sigmas`: Σ = D V_r diag(1/s_r²) V_rᵀ D, the same under any
gauge for a parameter with no part in the unseen directions), for the current rows and with
each addition a printer owner can make: a gauge block probed at 13 places
(:func:`block_poses`; Klipper's ``DELTA_ANALYZE MANUAL_HEIGHT``), Klipper's printed object,
both, a laser tracker at the same poses; the rods measured to ±0.1 mm with each where the
campaign has no prior on them (without the rods, heights at two levels leave the leans at σ
0.35° on the tutorial's printer, 0.50° from the bed alone: the leans trade with the scale).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.identifiability import RANK_RTOL

#: The planners whose poses are offered as an addition.
PLANNERS = ("default", "random")
#: Candidate poses each planner chooses among, and its seed (reproducible advice).
PLAN_CANDIDATES = 500
PLAN_SEED = 1


@dataclass(frozen=True)
class Option:
    """One campaign scored (module docstring): the current one (``kind="current"``) or it with
    one addition (``"setup"``, ``"printed-distance"``, ``"block"``, ``"poses"``)."""

    label: str
    kind: str
    rank: int
    n_seen: int
    sigma_min: float
    sigma_rank: float
    gain: float
    n_rows: int
    named: list = field(default_factory=list)

    @property
    def n_identified(self) -> int:
        """How many of the machine's named directions this campaign identifies."""
        return sum(e["status"] == "identified" for e in self.named)

    def key(self) -> tuple:
        """The ranking: rank, then σ_min, then the named directions identified, then σ_r."""
        return (-self.rank, -self.sigma_min, -self.n_identified, -self.sigma_rank)

    def to_dict(self) -> dict:
        return {"option": self.label, "kind": self.kind, "rank": self.rank, "of": self.n_seen,
                "sigma_min": self.sigma_min, "sigma_rank": self.sigma_rank, "gain": _finite(self.gain),
                "n_rows": self.n_rows,
                "named": [{"meaning": e["meaning"], "status": e["status"], "sigma": _finite(e["sigma"])}
                          for e in self.named]}


def _finite(v) -> float | None:
    """JSON has no infinity: None (the gain of a rank the current campaign lacks)."""
    return float(v) if np.isfinite(v) else None


@dataclass(frozen=True)
class Advice:
    """The current campaign and the additions, best first; ``gauge`` the directions no
    option sees ({name: coefficient} each, physical units), ``n_params`` the candidates."""

    current: Option
    options: tuple[Option, ...]
    names: tuple[str, ...]
    gauge: list
    notes: tuple[str, ...] = ()

    def lines(self) -> list[str]:
        """The advice in words, one statement per line (``pkmcal identifiability --suggest``)."""
        from pkmcal.identification.identifiability import format_direction

        P, g = len(self.names), len(self.gauge)
        out = [f"what to measure next: {len(self.options)} addition(s) ranked by the rank and the smallest singular "
               f"value of the identification Jacobian (unit-norm columns, noise-whitened) on the {P - g} of {P} "
               "parameter directions some available measurement sees:"]

        everyone = (self.current,) + tuple(self.options)
        unseen = [e["meaning"] for e in self.current.named if e.get("placement") and all(
            f["status"] == "unidentifiable" for o in everyone for f in o.named if f["meaning"] == e["meaning"])]

        def row(o: Option, head: str) -> str:
            words = "; ".join(f"{e['meaning']}: {e['status']}" for e in o.named if e["meaning"] not in unseen)
            g = f"x{o.gain:.3g}" if np.isfinite(o.gain) else "none before"
            sv = (f"smallest singular value {o.sigma_min:.3g} ({g})" if o.rank == o.n_seen else
                  f"smallest non-zero singular value {o.sigma_rank:.3g} ({g})")
            return f"  {head} {o.label}: rank {o.rank} of {o.n_seen}, {sv}" + (f"; {words}" if words else "")

        out.append(row(self.current, "now:"))
        out.extend(row(o, f"{k}.") for k, o in enumerate(self.options, start=1))
        if self.gauge:
            out.append(f"no available measurement sees {g} direction(s) (a gauge: fix them, e.g. with --fix auto):")
            out.extend(f"  {format_direction(d)}" for d in self.gauge)
        out.extend(f"no available measurement sees {m} (it only places prints on the bed)" for m in unseen)
        out.extend(f"note: {n}" for n in self.notes)
        return out

    def to_dict(self) -> dict:
        return {"current": self.current.to_dict(), "options": [o.to_dict() for o in self.options],
                "parameters": list(self.names), "gauge": self.gauge, "notes": list(self.notes)}


def _rows(machine, setup, poses, method, names, same_setup: bool = False):
    """Whitened rows of ``setup`` at ``poses``: (M, len(names)) on ``names``, and (M, s) on the
    free parameters of its sensor, its own nuisances. The current setup (``same_setup``)
    shares every name; another setup shares only the machine's parameters (its sensor is
    another instrument, whatever its parameters are called)."""
    from pkmcal.identification.identifiability import design_jacobian
    from pkmcal.identification.residuals import default_method

    method = method or default_method(setup, machine)
    J, ok, model_names = design_jacobian(machine, setup.sensor, setup.noise, poses, method)
    rows = J[ok].reshape(-1, J.shape[-1])
    shared = set(model_names) if same_setup else set(machine.param_names)
    A = np.zeros((rows.shape[0], len(names)))
    for j, n in enumerate(names):
        if n in shared:
            A[:, j] = rows[:, model_names.index(n)]
    own = [] if same_setup else [model_names.index(n) for n in setup.sensor.default_free]
    return A, rows[:, own], int(ok.sum())


def _eliminated(J: np.ndarray, S: np.ndarray) -> np.ndarray:
    """(I − P) J with P the projector onto range(S) (module docstring)."""
    if S.shape[1] == 0 or J.shape[0] == 0:
        return J
    U, s, _ = np.linalg.svd(S, full_matrices=False)
    U = U[:, s > RANK_RTOL * s[0]] if s.size and s[0] > 0 else U[:, :0]
    return J - U @ (U.T @ J)


def where_read(machine, sensor, poses: np.ndarray) -> np.ndarray:
    """The poses at which ``sensor`` reads when the machine is sent to ``poses``
    (``Sensor.measured_frames``: a Z probe's lowered onto the bed)."""
    return machine.poses_from_frame(sensor.measured_frames(machine.frame(poses)))


def _additions(machine, setup, poses, method, names, notes):
    """(label, kind, rows on ``names``) of every candidate addition (module docstring)."""
    from pkmcal.sensors.library import BUILTIN_SETUPS, builtin_setup

    out = []
    for name in BUILTIN_SETUPS:
        try:
            other = builtin_setup(name, machine)
        except PkmcalError:
            continue          # a setup that cannot measure this machine
        if other.sensor == setup.sensor:
            continue
        where = where_read(machine, other.sensor, poses)
        with np.errstate(invalid="ignore"):
            reached = machine.check_limits(where, margins=False).ok   # the machine goes where it reads
        if not reached.any():
            notes.append(f"{name}: not scored (the machine cannot reach where this sensor reads at these poses)")
            continue
        try:
            J, S, n = _rows(machine, other, where[reached], None, names)
        except PkmcalError as exc:
            notes.append(f"{name}: not scored ({exc})")
            continue
        if n:
            out.append((f"+ {name} at the same {n} poses", "setup", _eliminated(J, S)))
    if machine.kind == "linear-delta":
        out.append(_printed_object(machine, names))
    if "touch-probe" in setup.sensor.abilities and machine.held_on_one_plane:
        block = block_poses(machine)
        J, _, n = _rows(machine, setup, block, method, names, same_setup=True)
        out.append((f"+ a gauge block {BLOCK_HEIGHT:g} mm high probed at {n} places (Klipper: DELTA_ANALYZE "
                    "MANUAL_HEIGHT)", "block", J))
    for alg in PLANNERS:
        from pkmcal.planning.plan import plan_poses

        try:
            plan = plan_poses(machine, setup, len(poses), algorithm=alg, seed=PLAN_SEED, n_candidates=PLAN_CANDIDATES,
                              method=method, on_bed=False)      # lowered by where_read below
        except PkmcalError as exc:
            notes.append(f"planner '{alg}': no poses ({exc})")
            continue
        J, _, n = _rows(machine, setup, where_read(machine, setup.sensor, plan.poses), method, names,
                        same_setup=True)
        out.append((f"+ {n} more poses (planner '{alg}')", "poses", J))
    return out


def _printed_object(machine, names):
    """Klipper's printed calibration object on a delta: its 12 distances as an addition."""
    from pkmcal.io.klipper_analyze import object_point_pairs
    from pkmcal.mechanisms.pose_pairs import PosePairs
    from pkmcal.sensors.library import builtin_setup

    pairs = PosePairs(machine)
    p1, p2 = object_point_pairs()
    J, S, n = _rows(pairs, builtin_setup("printed-distance-klipper", pairs), np.c_[p1, p2], None, names)
    return (f"+ printed distances (Klipper's calibration object, DELTA_ANALYZE: {n} distances)", "printed-distance",
            _eliminated(J, S))


#: The second probe height advised for what a bed alone cannot see (a delta's rail leans):
#: a gauge block ("1-2-3 block" on its 2-inch side, mm) probed at :func:`block_poses`, as
#: Klipper's ``DELTA_ANALYZE MANUAL_HEIGHT`` enters it.
BLOCK_HEIGHT = 50.8
#: The rods measured with calipers (mm, a prior's σ) that the advice adds where none is given.
ROD_STD = 0.1
#: How far (mm) a carriage may stray over the print height before a lean counts as undetermined.
LEAN_STRAY = 0.05


def block_poses(machine, height: float = BLOCK_HEIGHT) -> np.ndarray:
    """(13, 3) where a gauge block of ``height`` is probed: the centre and 6 places on each of
    two rings at 0.4 and 0.75 of the machine's print radius (its workspace box's x half-width)."""
    r = 0.5 * float(np.diff(machine.workspace_box()[0])[0])
    xy = [(0.0, 0.0)] + [(f * r * np.cos(a), f * r * np.sin(a)) for f in (0.4, 0.75)
                         for a in 2 * np.pi * np.arange(6) / 6]
    return np.c_[np.array(xy), np.full(len(xy), float(height))]


def parameter_sigmas(rows: np.ndarray, names, which) -> dict[str, float]:
    """σ of each parameter ``which`` (internal units) from the whitened rows (M, P) on
    ``names``: the covariance on the directions the rows see (unit-norm columns, rank at
    :data:`RANK_RTOL`), the same for any gauge when the parameter has no part in the unseen
    directions; inf when it has (1e-6 of the unseen basis vector, unit-norm columns)."""
    names = list(names)
    col = np.linalg.norm(rows, axis=0)
    D = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
    _, s, Vt = np.linalg.svd(rows * D, full_matrices=True)
    full = np.zeros(len(names))
    full[:s.size] = s[:len(names)]
    r = int(np.sum(full > RANK_RTOL * full[0])) if full.size and full[0] > 0 else 0
    seen, unseen = Vt[:r], Vt[r:]
    out = {}
    for n in which:
        j = names.index(n)
        if unseen.size and np.max(np.abs(unseen[:, j])) > 1e-6:
            out[n] = float("inf")
        else:
            out[n] = float(D[j] * np.sqrt(np.sum((seen[:, j] / full[:r]) ** 2)))
    return out


def plane_held_advice(machine, setup, rows: np.ndarray, names, poses: np.ndarray, method: str | None,
                      held=(), rods_given: bool = False) -> dict | None:
    """What would determine the parameters a machine holds when every reading is on one plane
    (:attr:`~pkmcal.mechanisms.base.Mechanism.held_on_one_plane`: a delta's rail leans) for a
    touch probe on a bed, measured (issue 25 item 6): their largest σ from the current whitened
    ``rows`` on ``names`` (priors included), and with each addition a printer owner can make —
    a gauge block probed at :func:`block_poses` (Klipper's ``DELTA_ANALYZE MANUAL_HEIGHT``),
    Klipper's printed object, both, a laser tracker at the same poses — each with the rods
    measured to ±:data:`ROD_STD` unless ``rods_given``. The tolerance: the lean that strays a
    carriage :data:`LEAN_STRAY` mm over the machine's height (its workspace box). None when
    nothing applies. A named-direction entry (``meaning``, ``status``, ``sigma`` in degrees,
    ``tolerance``, ``remedy``, ``text``, ``note`` True: said, not warned)."""
    from fnmatch import fnmatchcase

    from pkmcal.sensors.library import builtin_setup

    names = tuple(names)
    plane = [n for n in names if any(fnmatchcase(n, p) for p in machine.held_on_one_plane)]
    if not plane or not setup.sensor.reads_one_plane or "touch-probe" not in setup.sensor.abilities:
        return None
    arms = [n for n in names if any(fnmatchcase(n, p) for p in machine.held_without_length)]
    rods = np.zeros((0 if rods_given else len(arms), len(names)))
    for k, n in enumerate([] if rods_given else arms):
        rods[k, names.index(n)] = 1.0 / ROD_STD
    height = float(np.diff(machine.workspace_box()[2])[0])
    tol = float(np.degrees(np.arctan(LEAN_STRAY / height)))

    def worst(*extra) -> float:
        return float(np.degrees(max(parameter_sigmas(np.vstack((rows,) + extra), names, plane).values())))

    with np.errstate(invalid="ignore"):
        block, _, _ = _rows(machine, setup, block_poses(machine), method, names, same_setup=True)
        printed = _printed_object(machine, names)[2]
        J, S, _ = _rows(machine, builtin_setup("laser-tracker", machine), poses, None, names)
    tracker = _eliminated(J, S)
    now = worst()
    options = [(f"a gauge block {BLOCK_HEIGHT:g} mm high probed at {len(block)} places (Klipper: DELTA_ANALYZE "
                "MANUAL_HEIGHT)", worst(rods, block)),
               ("Klipper's printed object (DELTA_ANALYZE)", worst(rods, printed)),
               ("both", worst(rods, block, printed)),
               (f"a laser tracker at these {len(poses)} poses", worst(rods, tracker))]
    best = min(v for _, v in options)
    status = "unidentifiable" if not np.isfinite(now) else "identified" if now <= tol else "not determined"
    was_held = [n for n in plane if n in set(held)]
    head = ("the rail leans: held at the machine file's values by this fit, as Klipper holds them; freed, these "
            "measurements would determine them to" if was_held else
            "the rail leans: these measurements determine them to")
    amount = "unbounded" if not np.isfinite(now) else f"{now:.2g} deg"
    text = (f"{head} sigma {amount} (largest of the {len(plane)}; tolerance {tol:.2g} deg: a carriage "
            f"{LEAN_STRAY:g} mm astray over the {height:.4g} mm height); with "
            + ("" if rods_given else f"the rods measured to ±{ROD_STD:g} mm and ")
            + "; ".join(f"{label}: {v:.2g} deg" for label, v in options)
            + (" — none reaches the tolerance" if best > tol else "")
            + "; no firmware holds leans (Klipper, Marlin): a lean found is squared on the frame")
    return {"meaning": "the rail leans", "status": status, "ratio": float("nan"), "sigma": now, "unit": "deg",
            "tolerance": tol, "tolerance_why": f"a carriage {LEAN_STRAY:g} mm astray over the {height:.4g} mm height",
            "remedy": "; ".join(f"{label}: sigma {v:.2g} deg" for label, v in options), "direction": {},
            "placement": False, "note": True, "held": was_held, "text": text}


def _score(E: np.ndarray, D: np.ndarray, U: np.ndarray) -> tuple[int, float, float]:
    """(rank, σ_min (0 below full rank), σ_r the smallest above the rank tolerance)."""
    s = np.linalg.svd((E * D) @ U, compute_uv=False) if U.shape[1] else np.zeros(0)
    full = np.zeros(U.shape[1])
    full[:s.size] = s[:U.shape[1]]
    if not full.size or full[0] <= 0:
        return 0, 0.0, 0.0
    rank = int(np.sum(full > RANK_RTOL * full[0]))
    return rank, float(full[-1]) if rank == full.size else 0.0, float(full[rank - 1])


def advise(machine, setup, poses: np.ndarray, *, method: str | None = None, free=None, fix=None) -> Advice:
    """Rank the candidate additions to the campaign ``machine`` + ``setup`` at ``poses``
    (module docstring); ``method``, ``free``, ``fix`` as in
    :func:`~pkmcal.identification.identifiability.identifiability`."""
    from pkmcal.identification.identifiability import _clean, named_directions_report
    from pkmcal.identification.residuals import Model, candidate_parameters, single_threaded_blas

    if setup.sensor.reads_pose_pairs:
        raise PkmcalError("--suggest ranks what to add to measurements of single poses; these are pairs of poses "
                          "(a printed object with probe heights). Run it on the probe heights alone (--setup "
                          "z-probe-klipper and their poses): it ranks the printed object among the additions")
    poses = machine.as_pose_array(poses)
    with np.errstate(invalid="ignore"):
        model = Model(machine, setup.sensor, setup.noise, machine.ik(poses[:1]),
                      setup.sensor.predict(machine.frame(poses[:1])))
    cand, _ = candidate_parameters(model, free, None if fix == "auto" else fix)
    names = tuple(model.names[i] for i in cand)
    notes: list[str] = []
    with single_threaded_blas():
        J0, _, n0 = _rows(machine, setup, poses, method, names, same_setup=True)
        adds = _additions(machine, setup, poses, method, names, notes)
        E_all = np.vstack([J0] + [J for _, _, J in adds])
        col = np.linalg.norm(E_all, axis=0)
        D = np.where(col > 0, 1.0 / np.where(col > 0, col, 1.0), 1.0)
        _, s, Vt = np.linalg.svd(E_all * D, full_matrices=True)
        r = int(np.sum(s > RANK_RTOL * s[0])) if s.size and s[0] > 0 else 0
        U, G = Vt[:r].T, Vt[r:].T
        directions = machine.named_directions()

        def option(label, kind, E) -> Option:
            rank, smin, sr = _score(E, D, U)
            named = named_directions_report(E, names, directions) if directions else []
            return Option(label, kind, rank, r, smin, sr, 0.0, E.shape[0], named)

        current = option(f"{setup.sensor.kind} at {n0} poses", "current", J0)
        scored = [option(label, kind, np.vstack([J0, J])) for label, kind, J in adds]

    def gain(o: Option) -> Option:
        """σ_min / σ_min of now on full rank, else σ_r / σ_r of now (the weakest seen)."""
        mine, base = (o.sigma_min, current.sigma_min) if o.rank == o.n_seen else (o.sigma_rank, current.sigma_rank)
        return replace(o, gain=mine / base if base > 0 else (float("inf") if mine > 0 else 1.0))

    scored = sorted((gain(o) for o in scored), key=Option.key)
    gauge = []
    if G.shape[1]:
        N = G * D[:, None]
        for k in range(N.shape[1]):
            v = N[:, k] / np.max(np.abs(N[:, k]))
            gauge.append(_clean(v if v[np.argmax(np.abs(v))] > 0 else -v, names, 1e-6))
    return Advice(gain(current), tuple(scored), names, gauge, tuple(notes))


__all__ = ["Advice", "BLOCK_HEIGHT", "Option", "PLANNERS", "advise", "block_poses", "parameter_sigmas",
           "plane_held_advice", "where_read"]
