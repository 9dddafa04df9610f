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

Timings: best of ``--repeats`` after a warm-up call (numba compile / cache load excluded),
as CPU time of this process (``*_ms``; robust when other jobs share the machine) and as
wall-clock time (``*_wall_ms``),
numba set to one thread (15–100 poses are far too few for threads to pay), BLAS limited to
one thread inside the engine. The last line of output is one JSON object.

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


def best_ms(fn, repeats: int) -> tuple[float, float]:
    """Best wall-clock and best CPU (process) time in ms over ``repeats`` calls after a warm-up."""
    fn()
    wall = cpu = np.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall * 1e3, cpu * 1e3


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
    }
    print("machine:", ", ".join(f"{k}={v}" for k, v in machine_info.items()))

    # -- IK-residual, 42 parameters, 15 poses -------------------------------------------
    nominal, real, setup, sim = paper1_problem(args.seed)
    q, y = sim.actuator_readings, sim.sensor_readings

    def ik(jac):
        return identify(nominal, setup, q=q, y=y, method="ik-residual", jac=jac)

    r_ik, r_ik_fd = ik("analytic"), ik("2-point")
    ik_wall, ik_ms = best_ms(lambda: ik("analytic"), args.repeats)
    ik_fd_wall, ik_fd_ms = best_ms(lambda: ik("2-point"), max(3, args.repeats // 4))
    print(f"ik-residual (42 params, 15 poses): analytic {ik_ms:.2f} ms CPU / {ik_wall:.2f} ms wall "
          f"({r_ik.nfev} evaluations), finite differences {ik_fd_ms:.2f} ms CPU / {ik_fd_wall:.2f} ms wall "
          f"({r_ik_fd.nfev} evaluations), "
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

    r_fk, r_fk_fd = fk("analytic"), fk("2-point")
    fk_wall, fk_ms = best_ms(lambda: fk("analytic"), max(3, args.repeats // 2))
    fk_fd_wall, fk_fd_ms = best_ms(lambda: fk("2-point"), 3)
    print(f"fk-residual (indicators, {len(q2)} poses, {len(r_fk.free)} free, gauge {', '.join(r_fk.gauge)}): "
          f"analytic {fk_ms:.2f} ms CPU / {fk_wall:.2f} ms wall ({r_fk.nfev} evaluations), "
          f"finite differences {fk_fd_ms:.2f} ms CPU / {fk_fd_wall:.2f} ms wall "
          f"({r_fk_fd.nfev} evaluations), max |estimate difference| "
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
        "efficiency_weighted": round(eff[True], 4),
        "efficiency_unweighted": round(eff[False], 4),
        "efficiency_rms_weighted": round(eff_rms[True], 4),
        "efficiency_rms_unweighted": round(eff_rms[False], 4),
        "bound_rms_mm": bound_rms,
        "weighted_rms_mm": actual[True],
        "unweighted_rms_mm": actual[False],
        "trials": args.trials,
        "machine": machine_info,
    }
    sys.stdout.flush()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
