"""Identification engine: speed against finite differences, and statistical efficiency.

Workloads (all on ``stewart-prototype``, data from
:func:`pkmcal.identification.simulation.simulate_campaign`):

* **IK-residual** (paper 1): full-pose sensor (``full-pose-paper1``: uniform noise ±0.025 mm,
  ±0.001 rad, legs ±0.01 mm), real machine = nominal + U(−5, 5) mm on every parameter
  (paper 1 §VI), 15 boundary configurations (corners of the ±box, paper 1 §IV), all 42
  parameters free. ``pkmcal.identify(method="ik-residual")`` timed end to end (residuals,
  identifiability check, solve, covariance) with the analytic Jacobian and with scipy's
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

Timings: after a warm-up call of each fit (numba compile / cache load excluded), rounds
that alternate the analytic and the finite-difference fit (so both see the same machine
load); the best of ``--repeats`` analytic and of ``max(3, repeats // 4)`` (IK) or 3 (FK)
finite-difference calls, as CPU time of this process (``*_ms``, the headline; robust when
other jobs share the machine) and as wall-clock time (``*_wall_ms``); numba set to one
thread (15–100 poses are far too few for threads to pay), BLAS limited to one thread inside
the engine. The machine (CPU, cores, versions, load average before and after) is recorded.

The two versions of each fit differ only in the Jacobian: the same residual function
(same whitening, same warm-started pose solves), the same Levenberg–Marquardt (MINPACK
``lmder``: ``ftol = xtol = gtol = 1e-12``, ``factor = 100``, Jacobian column scaling, cap
100·n evaluations), the same start (the nominal machine). The analytic fit calls ``lmder``
through ``scipy.optimize.leastsq``; the finite-difference fit through
``scipy.optimize.least_squares(jac="2-point", method="lm")``: scipy's forward differences
(2-point), step h_i = √ε·max(1, |θ_i|), one residual evaluation per free parameter and
Jacobian, fed to the same ``lmder`` (that wrapper added 0.55 ms to the analytic paper-1 fit,
best of 30, 2026-11-22, and evaluates one more Jacobian at the solution: one of the ~7 (IK)
or ~17 (FK) finite-difference Jacobians of these fits, measured as residual evaluations per
free parameter with seed 0 on 2026-11-22).

Reported beside the times, so that a speed-up splits into cost per Jacobian and number of
iterations: ``nfev`` (residual evaluations by the solver) and ``njev`` (Jacobian
evaluations); ``*_evaluations``, the calls of the method's ``evaluate``, residual-only and
with Jacobian (the finite-difference columns and the engine's start and end evaluations
included, some served from the pose cache); the final cost of both fits. The
finite-difference Jacobian is only accurate to ~1e-8 relative, so near the 1e-12
tolerances the finite-difference fit takes more iterations, and may stop at ``xtol`` at a
slightly higher cost. ``*_solve_ms`` is the CPU time inside the solver call of the fastest
run (residuals, Jacobians, MINPACK); the rest of ``*_ms`` is the same for both Jacobians:
the start evaluation with the noise covariance, the identifiability SVD, the end
evaluation and the covariance of the estimate.
The last line of output is one JSON object.

Usage: ``python benchmarks/identification.py [--repeats 20] [--trials 200] [--seed 0]``
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
    cmd = corners[rng.choice(probe.kept, size=n_poses, replace=False)]
    sim = simulate_campaign(nominal, real, setup, cmd, rng, ignore_limits=("leg_collision",))
    assert len(sim.kept) == n_poses
    return nominal, real, setup, sim


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=20)
    ap.add_argument("--trials", type=int, default=200)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    numba.set_num_threads(1)

    machine_info = {
        "cpu": cpu_model(), "cores": os.cpu_count(), "python": platform.python_version(),
        "numpy": np.__version__, "scipy": scipy.__version__, "numba": numba.__version__,
        "numba_threads": numba.get_num_threads(),
        "load_average_1min": os.getloadavg()[0],
        "platform": platform.platform(),
    }
    print("machine:", ", ".join(f"{k}={v}" for k, v in machine_info.items()))

    # -- IK-residual, 42 parameters, 15 poses -------------------------------------------
    nominal, real, setup, sim = paper1_problem(args.seed)
    q, y = sim.actuator_readings, sim.sensor_readings

    def ik(jac):
        return identify(nominal, setup, q=q, y=y, method="ik-residual", jac=jac)

    (r_ik, n_ik), (r_ik_fd, n_ik_fd) = counted(lambda: ik("analytic")), counted(lambda: ik("2-point"))
    t_ik, t_ik_fd = best_ms_pair(lambda: ik("analytic"), lambda: ik("2-point"), args.repeats, max(3, args.repeats // 4))
    ik_wall, ik_ms, ik_fd_wall, ik_fd_ms = t_ik["wall"], t_ik["cpu"], t_ik_fd["wall"], t_ik_fd["cpu"]
    print(f"ik-residual (42 params, 15 poses): analytic {ik_ms:.2f} ms CPU / {ik_wall:.2f} ms wall "
          f"(nfev {r_ik.nfev}, njev {r_ik.njev}), finite differences {ik_fd_ms:.2f} ms CPU / {ik_fd_wall:.2f} ms "
          f"wall (nfev {r_ik_fd.nfev}, {n_ik_fd['residual']} residual evaluations with the 2-point columns), "
          f"speed-up {ik_fd_ms / ik_ms:.1f}x (solver alone {t_ik['solve']:.2f} vs {t_ik_fd['solve']:.2f} ms, "
          f"{t_ik_fd['solve'] / t_ik['solve']:.1f}x), "
          f"max |estimate difference| {np.max(np.abs(r_ik.estimate - r_ik_fd.estimate)):.2e} mm, "
          f"mean |parameter error| before {np.mean(np.abs(nominal.params - real.params)):.3f} mm, "
          f"after {np.mean(np.abs(r_ik.estimate[:42] - real.params)):.4f} mm")

    # -- FK-residual, indicators, 100 poses ---------------------------------------------
    nom2 = builtin_machine("stewart-prototype")
    real2 = builtin_machine("stewart-prototype-real")
    setup2 = builtin_setup("indicators-prototype")
    rng = np.random.default_rng(args.seed + 1)
    half = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])
    cmd = nom2.home_pose + rng.uniform(-1.0, 1.0, (130, 6)) * half
    sim2 = simulate_campaign(nom2, real2, setup2, cmd, rng, ignore_limits=("leg_collision",))
    keep = sim2.kept[:100]
    idx = np.searchsorted(sim2.kept, keep)
    q2, y2, c2 = sim2.actuator_readings[idx], sim2.sensor_readings[idx], sim2.commanded[keep]

    def fk(jac):
        return identify(nom2, setup2, q=q2, y=y2, commanded=c2, method="fk-residual", jac=jac)

    (r_fk, n_fk), (r_fk_fd, n_fk_fd) = counted(lambda: fk("analytic")), counted(lambda: fk("2-point"))
    t_fk, t_fk_fd = best_ms_pair(lambda: fk("analytic"), lambda: fk("2-point"), max(3, args.repeats // 2), 3)
    fk_wall, fk_ms, fk_fd_wall, fk_fd_ms = t_fk["wall"], t_fk["cpu"], t_fk_fd["wall"], t_fk_fd["cpu"]
    print(f"fk-residual (indicators, {len(q2)} poses, {len(r_fk.free)} free, gauge {', '.join(r_fk.gauge)}): "
          f"analytic {fk_ms:.2f} ms CPU / {fk_wall:.2f} ms wall (nfev {r_fk.nfev}, njev {r_fk.njev}), "
          f"finite differences {fk_fd_ms:.2f} ms CPU / {fk_fd_wall:.2f} ms wall "
          f"(nfev {r_fk_fd.nfev}, {n_fk_fd['residual']} residual evaluations with the 2-point columns), "
          f"speed-up {fk_fd_ms / fk_ms:.1f}x (solver alone {t_fk['solve']:.2f} vs {t_fk_fd['solve']:.2f} ms, "
          f"{t_fk_fd['solve'] / t_fk['solve']:.1f}x), max |estimate difference| "
          f"{np.max(np.abs(r_fk.estimate - r_fk_fd.estimate)):.2e} mm")

    # -- efficiency, paper 1 set-up -------------------------------------------------------
    truth = real.params
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

    out = {
        "ik_residual_ms": round(ik_ms, 3),
        "ik_residual_fd_ms": round(ik_fd_ms, 3),
        "ik_residual_speedup": round(ik_fd_ms / ik_ms, 2),
        "fk_residual_ms": round(fk_ms, 3),
        "fk_residual_fd_ms": round(fk_fd_ms, 3),
        "fk_residual_speedup": round(fk_fd_ms / fk_ms, 2),
        "fk_residual_poses": int(len(q2)),
        "ik_residual_wall_ms": round(ik_wall, 3),
        "ik_residual_fd_wall_ms": round(ik_fd_wall, 3),
        "fk_residual_wall_ms": round(fk_wall, 3),
        "fk_residual_fd_wall_ms": round(fk_fd_wall, 3),
        "fd_jacobian": "scipy least_squares jac='2-point' (forward differences, step sqrt(eps)*max(1,|theta|))",
        "solver": "MINPACK lmder (Levenberg-Marquardt), ftol=xtol=gtol=1e-12, same start for both Jacobians",
        "ik_residual_solve_ms": round(t_ik["solve"], 3),
        "ik_residual_fd_solve_ms": round(t_ik_fd["solve"], 3),
        "fk_residual_solve_ms": round(t_fk["solve"], 3),
        "fk_residual_fd_solve_ms": round(t_fk_fd["solve"], 3),
        "ik_residual_cost": r_ik.cost,
        "ik_residual_fd_cost": r_ik_fd.cost,
        "fk_residual_cost": r_fk.cost,
        "fk_residual_fd_cost": r_fk_fd.cost,
        "ik_residual_nfev": r_ik.nfev,
        "ik_residual_njev": r_ik.njev,
        "ik_residual_evaluations": n_ik,
        "ik_residual_fd_nfev": r_ik_fd.nfev,
        "ik_residual_fd_evaluations": n_ik_fd,
        "fk_residual_nfev": r_fk.nfev,
        "fk_residual_njev": r_fk.njev,
        "fk_residual_evaluations": n_fk,
        "fk_residual_fd_nfev": r_fk_fd.nfev,
        "fk_residual_fd_evaluations": n_fk_fd,
        "ik_residual_max_estimate_difference_mm": float(np.max(np.abs(r_ik.estimate - r_ik_fd.estimate))),
        "fk_residual_max_estimate_difference_mm": float(np.max(np.abs(r_fk.estimate - r_fk_fd.estimate))),
        "efficiency_weighted": round(eff[True], 4),
        "efficiency_unweighted": round(eff[False], 4),
        "efficiency_rms_weighted": round(eff_rms[True], 4),
        "efficiency_rms_unweighted": round(eff_rms[False], 4),
        "bound_rms_mm": bound_rms,
        "weighted_rms_mm": actual[True],
        "unweighted_rms_mm": actual[False],
        "trials": args.trials,
        "repeats": args.repeats,
        "machine": {**machine_info, "load_average_1min_after": os.getloadavg()[0]},
    }
    sys.stdout.flush()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
