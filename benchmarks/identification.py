"""Identification engine: speed against finite differences, and statistical efficiency.

Workloads (all on ``stewart-prototype``, data from
:func:`pkmcal.identification.simulation.simulate_campaign`):

* **IK-residual** (paper 1): full-pose sensor (``full-pose-paper1``: uniform noise ±0.025 mm,
  ±0.001 rad, legs ±0.01 mm), real machine = nominal + U(−5, 5) mm on every parameter
  (paper 1 §VI), 15 boundary configurations (corners of the ±box, paper 1 §IV), all 42
  parameters free. ``pkmcal.identify(method="ik-residual")`` timed end to end (residuals,
  identifiability check, solve, covariance; when the rank certificate proves full rank,
  the full identifiability report and its weak-direction warnings, one SVD of the 42 × 42
  triangle, ~0.3 ms, are computed on first read and not timed here) with the analytic Jacobian and with scipy's
  2-point finite-difference Jacobian of the same residual function (``jac="2-point"``).
* **FK-residual** (paper 2): 3 dial indicators (``indicators-prototype``), real machine
  = ``stewart-prototype-real`` (Table 4), 100 random poses, automatic gauge (39 free).
* **Efficiency** (paper 1 set-up, Monte Carlo over noise draws, fixed real machine and
  poses): for the weighted (GLS) and unweighted fits,

      efficiency = bound_rms / actual_rms,
      actual_rms = sqrt(mean over trials and identifiable parameters of (θ̂ − θ_real)²),
      bound_rms  = sqrt(trace((JᵀΣ⁻¹J)⁻¹) / p)  at the real parameters,

  (JᵀΣ⁻¹J)⁻¹ being the Gauss–Markov bound (best linear unbiased; the Cramér–Rao bound for
  Gaussian noise). 1 = as good as the bound; the unweighted fit is expected below 1.
  ``efficiency_rms_*`` is this mm-rms ratio. On this set-up it is dominated by the two
  weakest directions (σ ratio ~1e-4, bound ~3.6 mm), so its Monte Carlo estimate is noisy
  (few effective degrees of freedom) and nonlinear; the headline ``efficiency_*`` is the
  whitened version, averaging over all 42 directions equally:

      efficiency = p / mean_trials[(θ̂ − θ)ᵀ C⁻¹ (θ̂ − θ)],   C = (JᵀΣ⁻¹J)⁻¹, p = 42,

  which is 1 for an unbiased estimator attaining the bound and trace(C⁻¹ C_est)/p < 1 otherwise.

Problems: each fit is timed on ``--problems`` instances (IK: seeds seed … seed+P−1, each
its own random real machine and 15 corners; FK: P draws of 100 poses). How many
iterations the finite-difference fit needs changes from instance to instance (its Jacobian
is accurate to ~1e-8 relative, and the weak directions, σ ratio ~1e-4, amplify that), so
one instance gives a speed-up that depends on luck; the headline figures are medians over
the instances, and every instance's figures are in ``*_problems``.

Timings per instance: after a warm-up call of each fit (numba compile / cache load
excluded), rounds that alternate the analytic and the finite-difference fit (so both see
the same machine load); the best of ``--repeats`` analytic and of ``max(3, repeats // 4)``
(IK) or 3 (FK) finite-difference calls, as CPU time of this process (``*_ms``, the
headline; robust when other jobs share the machine) and as wall-clock time
(``*_wall_ms``); numba set to one thread (15–100 poses are far too few for threads to pay),
BLAS limited to one thread inside the engine. The machine (CPU, cores, versions, load
average before and after) is recorded.

The two versions of each fit differ only in the Jacobian: the same residual function
(same whitening, same warm-started pose solves, FK polished to rounding), the same
Levenberg–Marquardt (MINPACK ``lmder``: the engine's tolerances, ``factor = 100``, Jacobian
column scaling, cap 100·n evaluations), the same start (the nominal machine). The analytic
fit calls ``lmder`` through ``scipy.optimize.leastsq``; the finite-difference fit through
``scipy.optimize.least_squares(jac="2-point", method="lm")``: scipy's forward differences,
step h_i = √ε·max(1, |θ_i|), one residual evaluation per free parameter and Jacobian, fed
to the same ``lmder``. That wrapper also evaluates one more Jacobian at the solution, as a
user of it pays: one of the ~15 finite-difference Jacobians of these fits (6–7 % of their
residual evaluations, from the ``fd_evaluations`` and ``fd_nfev`` of a run on 2026-11-22).

Where the time goes (:func:`anatomy`, per instance, medians reported): ``*_solve_ms`` the
CPU time inside the solver call (residuals, Jacobians, MINPACK); ``*_solver_only_ms``
MINPACK's own share, measured by replaying the recorded residuals and Jacobians through
the same call; ``*_jacobian_us`` one analytic Jacobian against ``*_fd_jacobian_us`` = n
residual evaluations, the forward-difference Jacobian, whose ratio
``*_jacobian_speedup`` is the speed-up per Jacobian independent of iteration counts. The
rest of ``*_ms`` is the same for both Jacobians: the start evaluation with the noise
covariance, the identifiability check, the end evaluation and the covariance of the
estimate. However cheap the residuals and Jacobians inside the solver were made, the fit
speed-up could not exceed ``*_speedup_bound`` = (time of the finite-difference fit) /
(that fixed part + MINPACK's share). ``nfev``/``njev`` and
``*evaluations`` (calls of the method's ``evaluate``, residual-only and with Jacobian)
split the speed-up into cost per Jacobian and number of iterations.
The last line of output is one JSON object.

Usage: ``python benchmarks/identification.py [--repeats 20] [--trials 1000] [--seed 0] [--problems 5]
[--quick]`` (``--quick``: one repeat, 10 trials, one problem of each fit; key ``quick``)
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import sys
import time

import numba
import numpy as np
import scipy

from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import perturb_machine, simulate_campaign
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _quick import parse_args  # noqa: E402  (benchmarks/_quick.py)
from kinematics import cpu_model  # noqa: E402  (benchmarks/kinematics.py)


class SolverClock:
    """CPU time spent inside the engine's least-squares call (``engine._least_squares``)
    during one ``identify``, so that a fit's time splits into the solve (residuals,
    Jacobians, MINPACK) and the fixed costs around it (start evaluation with covariance,
    identifiability SVD, end evaluation, covariance of the estimate)."""

    def __init__(self):
        from pkmcal.identification import engine

        self._engine, self._orig, self.cpu = engine, engine._least_squares, 0.0

    def __enter__(self):
        def timed(*args, **kwargs):
            c0 = time.process_time()
            try:
                return self._orig(*args, **kwargs)
            finally:
                self.cpu += time.process_time() - c0

        self._engine._least_squares = timed
        return self

    def __exit__(self, *exc):
        self._engine._least_squares = self._orig


def best_ms_pair(fast, slow, repeats_fast: int, repeats_slow: int) -> tuple[dict, dict]:
    """Best times of two functions after a warm-up each, over alternating rounds (both see
    the same load): each round runs ``fast`` ⌈repeats_fast / repeats_slow⌉ times and
    ``slow`` once. Per function: best ``wall`` and ``cpu`` ms, and ``solve`` the solver's
    CPU ms in the run with the best CPU time."""
    fast(), slow()
    per_round = max(1, -(-repeats_fast // repeats_slow))
    best = {"fast": {"wall": np.inf, "cpu": np.inf, "solve": np.nan},
            "slow": {"wall": np.inf, "cpu": np.inf, "solve": np.nan}}
    with SolverClock() as clock:
        for _ in range(repeats_slow):
            for name, fn, n in (("fast", fast, per_round), ("slow", slow, 1)):
                b = best[name]
                for _ in range(n):
                    clock.cpu = 0.0
                    t0, c0 = time.perf_counter(), time.process_time()
                    fn()
                    wall, cpu = (time.perf_counter() - t0) * 1e3, (time.process_time() - c0) * 1e3
                    b["wall"] = min(b["wall"], wall)
                    if cpu < b["cpu"]:
                        b["cpu"], b["solve"] = cpu, clock.cpu * 1e3
    return best["fast"], best["slow"]


def counted(fn):
    """``fn()`` and how many residual-only and Jacobian evaluations its fit made (every call
    of the method's ``evaluate``, finite-difference columns included; not timed)."""
    from pkmcal.identification import residuals

    counts = {"residual": 0, "jacobian": 0}
    saved = {}
    for cls in (residuals.IKResidual, residuals.FKResidual):
        saved[cls] = cls.evaluate

        def evaluate(self, theta, jac=True, cov=True, _orig=cls.evaluate):
            counts["jacobian" if jac else "residual"] += 1
            return _orig(self, theta, jac, cov)

        cls.evaluate = evaluate
    try:
        result = fn()
    finally:
        for cls, orig in saved.items():
            cls.evaluate = orig
    return result, counts


class _Proxy:
    """Stands in for the engine's objective inside ``_least_squares``: either records what
    the real one returns, or replays those records (so the solver retraces the same path
    at the cost of a list lookup per call)."""

    def __init__(self, obj=None, record=None):
        self.obj, self.f, self.J = obj, [], []
        if record is not None:
            self.f, self.J = iter(record.f), iter(record.J)

    def _call(self, which: str, x):
        records = getattr(self, which)
        if self.obj is None:
            return next(records)
        out = getattr(self.obj, "fun" if which == "f" else "jac")(x)
        records.append(out.copy())
        return out

    def fun(self, x):
        return self._call("f", x)

    def jac(self, x):
        return self._call("J", x)


def anatomy(fit, repeats: int) -> dict:
    """Where an analytic fit's time goes: one ``fit()`` is recorded; then, best of
    ``repeats`` CPU times,

    * ``solver_only_ms``: MINPACK (and scipy's wrapper) replaying the recorded residuals and
      Jacobians, i.e. the solver's own linear algebra, which no Jacobian can remove;
    * ``residual_us`` / ``jacobian_us``: one residual evaluation at a new point, and one
      analytic Jacobian after it (as the solver asks: residual first, then Jacobian at the
      same point), on the fit's objective;
    * ``fd_jacobian_us`` = n_free · ``residual_us``: the forward-difference Jacobian's cost
      (one residual per free parameter), and ``jacobian_speedup`` its ratio to
      ``jacobian_us``: the speed-up per Jacobian, independent of iteration counts.
    """
    from pkmcal.identification import engine

    orig = engine._least_squares
    seen = {}

    def recording(obj, x0, **kw):
        proxy = _Proxy(obj)
        sol = orig(proxy, x0, **kw)
        seen.update(obj=obj, x0=x0.copy(), kw=kw, record=proxy, x=sol.x.copy())
        return sol

    engine._least_squares = recording
    try:
        fit()
    finally:
        engine._least_squares = orig
    obj, x0, kw, rec = seen["obj"], seen["x0"], seen["kw"], seen["record"]

    def best_cpu_us(fn, n):
        fn()
        best = np.inf
        for _ in range(n):
            c0 = time.process_time()
            fn()
            best = min(best, time.process_time() - c0)
        return best * 1e6

    solver_only = best_cpu_us(lambda: orig(_Proxy(record=rec), x0, **kw), repeats) / 1e3
    # two points that alternate, so that every call misses the objective's pose cache
    xa, xb = seen["x"], seen["x"] + 1e-6 * np.maximum(1.0, np.abs(seen["x"]))
    flip = itertools.cycle((xa, xb))
    n_calls = 20
    t_res = best_cpu_us(lambda: [obj.fun(next(flip)) for _ in range(n_calls)], repeats) / n_calls

    def res_and_jac():
        for _ in range(n_calls):
            x = next(flip)
            obj.fun(x)
            obj.jac(x)

    t_jac = best_cpu_us(res_and_jac, repeats) / n_calls - t_res
    n_free = x0.size
    return {"solver_only_ms": round(solver_only, 3), "residual_us": round(t_res, 2),
            "jacobian_us": round(t_jac, 2), "fd_jacobian_us": round(n_free * t_res, 2),
            "jacobian_speedup": round(n_free * t_res / t_jac, 2),
            "solver_residuals": len(rec.f), "solver_jacobians": len(rec.J)}


def boundary_corners(machine):
    """Paper 1 §IV: the 64 corners of a ±box around home (those the nominal machine reaches)."""
    half = np.array([15.0, 15.0, 8.0, *np.deg2rad([6.0, 6.0, 6.0])])
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=6))) * half + machine.home_pose
    return corners[machine.check_limits(corners).ok]


def paper1_problem(seed: int, n_poses: int = 15):
    """Real machine = nominal + U(−5, 5) mm; 15 corners the real machine reaches, at random."""
    rng = np.random.default_rng(seed)
    nominal = builtin_machine("stewart-prototype")
    setup = builtin_setup("full-pose-paper1")
    real = perturb_machine(nominal, 5.0, rng, name="paper1-real")
    corners = boundary_corners(nominal)
    probe = simulate_campaign(nominal, real, setup, corners, rng, ignore_limits=("leg_collision",))
    return nominal, real, setup, probe.subset(np.sort(rng.choice(len(probe.kept), size=n_poses, replace=False)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--trials", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--problems", type=int, default=5,
                    help="problem instances per fit (real machines / pose draws); times are medians over them")
    args = parse_args(ap, None, repeats=1, trials=10, problems=1)
    numba.set_num_threads(1)

    machine_info = {
        "cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
        "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
        "numba_threads": numba.get_num_threads(),
        "load_average_1min": os.getloadavg()[0],
        "platform": platform.platform(),
    }
    print("machine:", ", ".join(f"{k}={v}" for k, v in machine_info.items()))

    # -- the two fits, each on --problems instances ---------------------------------------
    def compare(label, problems, fit, repeats_fast, repeats_slow):
        """Per problem: counts, best times of the analytic and finite-difference fits (in
        alternating rounds) and the analytic fit's anatomy; then medians over problems."""
        rows = []
        for k, prob in enumerate(problems):
            (r_a, n_a), (r_fd, n_fd) = counted(lambda: fit(prob, "analytic")), counted(lambda: fit(prob, "2-point"))
            t_a, t_fd = best_ms_pair(lambda: fit(prob, "analytic"), lambda: fit(prob, "2-point"),
                                     repeats_fast, repeats_slow)
            parts = anatomy(lambda: fit(prob, "analytic"), repeats_fast)
            row = {"ms": t_a["cpu"], "fd_ms": t_fd["cpu"], "wall_ms": t_a["wall"], "fd_wall_ms": t_fd["wall"],
                   "solve_ms": t_a["solve"], "fd_solve_ms": t_fd["solve"], "speedup": t_fd["cpu"] / t_a["cpu"],
                   "nfev": r_a.nfev, "njev": r_a.njev, "fd_nfev": r_fd.nfev, "evaluations": n_a,
                   "fd_evaluations": n_fd, "cost": r_a.cost, "fd_cost": r_fd.cost, "free": len(r_a.free),
                   "max_estimate_difference_mm": float(np.max(np.abs(r_a.estimate - r_fd.estimate))), **parts}
            row["speedup_bound"] = row["fd_ms"] / (row["ms"] - row["solve_ms"] + parts["solver_only_ms"])
            rows.append(row)
            print(f"{label} problem {k}: analytic {row['ms']:.2f} ms CPU (nfev {r_a.nfev}, njev {r_a.njev}; "
                  f"solver {row['solve_ms']:.2f} ms of which MINPACK alone {parts['solver_only_ms']:.2f} ms; "
                  f"residual {parts['residual_us']:.1f} us, Jacobian {parts['jacobian_us']:.1f} us), "
                  f"finite differences {row['fd_ms']:.2f} ms CPU (nfev {r_fd.nfev}, {n_fd['residual']} residual "
                  f"evaluations; {parts['fd_jacobian_us']:.0f} us per Jacobian = {parts['jacobian_speedup']:.1f}x the "
                  f"analytic one), speed-up {row['speedup']:.1f}x, cost {r_a.cost:.10g} vs {r_fd.cost:.10g}, "
                  f"max |estimate difference| {row['max_estimate_difference_mm']:.2e} mm", flush=True)
        med = {key: float(np.median([r[key] for r in rows]))
               for key in ("ms", "fd_ms", "wall_ms", "fd_wall_ms", "solve_ms", "fd_solve_ms", "speedup",
                           "solver_only_ms", "residual_us", "jacobian_us", "fd_jacobian_us", "jacobian_speedup",
                           "speedup_bound")}
        print(f"{label}: median over {len(rows)} problems: analytic {med['ms']:.2f} ms, finite differences "
              f"{med['fd_ms']:.2f} ms, speed-up {med['speedup']:.1f}x (range "
              f"{min(r['speedup'] for r in rows):.1f}-{max(r['speedup'] for r in rows):.1f}x; at most "
              f"{med['speedup_bound']:.1f}x with free residuals and Jacobians in the solver); per Jacobian "
              f"{med['jacobian_speedup']:.1f}x", flush=True)
        return med, rows

    ik_problems = [paper1_problem(args.seed + k) for k in range(args.problems)]

    def ik(prob, jac):
        nominal, _, setup, sim = prob
        return identify(nominal, setup, q=sim.actuator_readings, y=sim.sensor_readings, method="ik-residual", jac=jac)

    ik_med, ik_rows = compare("ik-residual (42 params, 15 poses)", ik_problems, ik, args.repeats,
                              max(3, args.repeats // 4))
    nominal, real, setup, sim = ik_problems[0]

    nom2 = builtin_machine("stewart-prototype")
    real2 = builtin_machine("stewart-prototype-real")
    setup2 = builtin_setup("indicators-prototype")

    def fk_problem(seed):
        """100 random poses (of 130 drawn, those the real machine reaches) within ±20 mm,
        ±10 mm in z, ±8°."""
        rng = np.random.default_rng(seed)
        half = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])
        cmd = nom2.home_pose + rng.uniform(-1.0, 1.0, (130, 6)) * half
        sim2 = simulate_campaign(nom2, real2, setup2, cmd, rng, ignore_limits=("leg_collision",))
        keep = sim2.kept[:100]
        idx = np.searchsorted(sim2.kept, keep)
        return sim2.actuator_readings[idx], sim2.sensor_readings[idx], sim2.commanded[keep]

    def fk(prob, jac):
        q2, y2, c2 = prob
        return identify(nom2, setup2, q=q2, y=y2, commanded=c2, method="fk-residual", jac=jac)

    fk_problems = [fk_problem(args.seed + 1000 + k) for k in range(args.problems)]
    fk_med, fk_rows = compare("fk-residual (indicators, 100 poses)", fk_problems, fk, max(3, args.repeats // 2), 3)

    # -- efficiency, paper 1 set-up -------------------------------------------------------
    truth = real.params[:42]  # the 42 parameters estimated (the leg gains are held at 1)
    exact = identify(real, setup, q=sim.actuator_true, y=sim.sensor_true, method="ik-residual")
    bound_rms = float(np.sqrt(np.trace(exact.uncertainty.covariance_prior) / 42))
    noise_rng = np.random.default_rng(args.seed + 2)
    errors = {True: [], False: []}
    t0 = time.perf_counter()
    for _ in range(args.trials):
        e_y, e_q = setup.noise.sample(noise_rng, sim.sensor_true.shape, sim.actuator_true.shape)
        for w in (True, False):
            res = identify(nominal, setup, q=sim.actuator_true + e_q, y=sim.sensor_true + e_y,
                           method="ik-residual", weighted=w)
            errors[w].append(res.estimate[:42] - truth)
    mc_s = time.perf_counter() - t0
    actual = {w: float(np.sqrt(np.mean(np.square(errors[w])))) for w in (True, False)}
    eff_rms = {w: bound_rms / actual[w] for w in (True, False)}
    Cinv = np.linalg.inv(exact.uncertainty.covariance_prior)
    eff = {w: 42.0 / float(np.mean(np.einsum("ti,ij,tj->t", np.array(errors[w]), Cinv, np.array(errors[w]))))
           for w in (True, False)}
    print(f"efficiency over {args.trials} noise draws ({mc_s:.1f} s): bound rms {bound_rms:.5f} mm; "
          f"weighted rms {actual[True]:.5f} mm (rms efficiency {eff_rms[True]:.3f}, whitened {eff[True]:.3f}); "
          f"unweighted rms {actual[False]:.5f} mm (rms efficiency {eff_rms[False]:.3f}, whitened {eff[False]:.3f})")

    # "<fit>_<figure>" for both fits, from compare()'s medians
    out = {f"{fit}_{figure}": round(med[figure], 3)
           for fit, med in (("ik_residual", ik_med), ("fk_residual", fk_med)) for figure in med}
    out.update({
        "fk_residual_poses": 100,
        "problems": args.problems,
        "statistic": "median over problems of the best CPU time over repeats",
        "fd_jacobian": "scipy least_squares jac='2-point' (forward differences, step sqrt(eps)*max(1,|theta|))",
        "solver": "MINPACK lmder (Levenberg-Marquardt), ftol=xtol=gtol=engine default, same start for both Jacobians",
        "ik_residual_problems": ik_rows,
        "fk_residual_problems": fk_rows,
        "efficiency_weighted": round(eff[True], 4),
        "efficiency_unweighted": round(eff[False], 4),
        "efficiency_rms_weighted": round(eff_rms[True], 4),
        "efficiency_rms_unweighted": round(eff_rms[False], 4),
        "bound_rms_mm": bound_rms,
        "weighted_rms_mm": actual[True],
        "unweighted_rms_mm": actual[False],
        "trials": args.trials,
        "repeats": args.repeats,
        "quick": args.quick,
        "machine": {**machine_info, "load_average_1min_after": os.getloadavg()[0]},
    })
    sys.stdout.flush()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
