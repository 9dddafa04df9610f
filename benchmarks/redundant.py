"""Paper 3 (Jeon et al., CIRP 2010) §3 reproduced in simulation, plus a Monte Carlo.

For each machine (``planar-2dof-3act``, ``planar-3dof-4act``):

1. *Reproduction*: the real machine is the nominal one plus the paper's identified errors
   (Table 1 / Table 2) — our reconstruction of "the machine they had". 30 calibration
   poses and 8 (case 1) / 6 (case 2) held-out poses, uniform in the workspace (seeded);
   tracker noise σ = 0.010 mm per axis (AT901: ±10 µm + 5 µm/m), encoder noise σ = 1e-5 rad
   (rotary) / 1 µm (linear); actuator stiffness and in-plane tool load as stated in
   :data:`pkmcal.reproduce.paper3.CASES` (the identifier never sees them).
2. *Monte Carlo*: ``--machines`` random real machines (parameter errors σ = 0.2 mm for
   lengths, 0.05° for angles and rotary encoder offsets, 0.2 mm for linear encoder
   offsets, 0.1 mm for the tool point; stiffness of each actuator ×U(0.5, 2)), each with
   fresh poses and noise.

Methods (:data:`pkmcal.reproduce.paper3_experiment.METHODS`, each a configuration of the
engine's ``identify(method="projection")``, see :func:`~pkmcal.reproduce.paper3_experiment.fit_redundant`):
``projection`` (re-linearised, weighted), ``projection-single`` (the paper's one
linearisation, weighted), ``projection-unweighted`` (re-linearised, rows in raw mm and rad),
baselines ``ignore-redundancy`` and ``actuator-subset`` (first n actuators). "rank r/n":
rank of the requested free set / its size (the engine fixes the rest as the gauge); ± 1σ:
the engine's reported standard deviation.
Improvement = 100·(1 − mean held-out error after / before). Last line: one JSON object.

Run: ``python benchmarks/redundant.py [--machines 100] [--seed 0] [--quick]`` (``--quick``: the
same reproduction, a Monte Carlo of 2 machines; key ``quick``)
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from _quick import parse_args  # benchmarks/_quick.py
from pkmcal.reproduce.paper3 import (CASES, LOAD_N, N_CALIB, TRACKER_STD, case_models, gauge_equivalent, real_setup,
                                     table_experiment)
from pkmcal.reproduce.paper3_experiment import METHODS, calibration_experiment


def _angle_flags(mech, sensor) -> dict[str, bool]:
    """Which parameters of the machine and of its sensor are angles (rad inside, degrees in
    the table), as both declare them (``param_is_angle``)."""
    return dict(zip(mech.param_names + sensor.param_names, mech.param_is_angle + sensor.param_is_angle))


def _random_errors(mech, rng):
    return {n: rng.normal() * (np.deg2rad(0.05) if a else 0.2) for n, a in zip(mech.param_names, mech.param_is_angle)}


def _summ(res):
    row = {"before_mean_mm": float(res.before.mean()), "max_before_mm": float(res.before.max())}
    for m in res.after:
        row[m] = {"improvement_pct": res.improvement_pct(m), "mean_after_mm": float(res.after[m].mean()),
                  "max_after_mm": float(res.after[m].max()), "rank": res.fits[m].identifiability.rank,
                  "n_free": res.fits[m].identifiability.n_params}
    return row


def run(case, n_machines, seed):
    setup = CASES[case]
    nominal, sensor, noise, _, _ = models = case_models(case)
    rng = np.random.default_rng(seed)
    # 1. reproduction with the paper's identified errors as the real machine
    repro = table_experiment(case, rng, models)
    # 2. Monte Carlo over random machines, all parameters in error, identifiable set free
    free = tuple(n for n in nominal.param_names if n not in setup["frame"] + setup["gauge"]) + ("target.x", "target.y")
    rows = []
    t0 = time.perf_counter()
    for _ in range(n_machines):
        err = _random_errors(nominal, rng)
        for f in setup["frame"]:
            err[f] = 0.0      # the measurement frame is defined by these joints (paper 3 §3.1)
        real = nominal.with_deltas(err)
        real_sensor = sensor.with_deltas({"target.x": rng.normal() * 0.1, "target.y": rng.normal() * 0.1})
        K = setup["stiffness"] * rng.uniform(0.5, 2.0, size=nominal.n_actuators)
        calib = nominal.sample_poses(N_CALIB, rng)
        check = nominal.sample_poses(setup["n_check"], rng)
        res = calibration_experiment(nominal, sensor, real, real_setup(real_sensor, noise, K), calib, check, rng,
                                     free=free, methods=METHODS)
        rows.append(_summ(res))
    dt = time.perf_counter() - t0
    imp = {m: np.array([r[m]["improvement_pct"] for r in rows]) for m in METHODS}
    mc = {
        "machines": n_machines,
        "seconds_per_machine": dt / max(n_machines, 1),
        "max_before_mm_mean": float(np.mean([r["max_before_mm"] for r in rows])),
        "free": list(free),
    }
    for m in METHODS:
        mc[m] = {"improvement_mean_pct": float(imp[m].mean()), "improvement_worst_pct": float(imp[m].min()),
                 "max_after_mm_mean": float(np.mean([r[m]["max_after_mm"] for r in rows])),
                 "max_after_mm_worst": float(np.max([r[m]["max_after_mm"] for r in rows]))}
    gauge_poses = nominal.sample_poses(N_CALIB, np.random.default_rng([seed, 7]))
    truth = gauge_equivalent(nominal, sensor, gauge_poses, noise, dict(setup["table"], **setup["table_tool"]),
                             setup["free"], setup["gauge"])
    fit = repro.fits["projection"]
    ident = []
    is_angle = _angle_flags(nominal, sensor)
    for name_, d, sd in zip(fit.free, fit.x - fit.initial[fit.free_index], fit.std):
        ang = is_angle[name_]
        f = np.rad2deg if ang else float
        ident.append((name_, float(f(setup["table"].get(name_, setup["table_tool"].get(name_, 0.0)))),
                      float(f(truth[name_])), float(f(d)), float(f(sd)), "deg" if ang else "mm"))
    return _summ(repro), mc, ident


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--machines", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = parse_args(ap, None, machines=2)
    out = {"quick": args.quick}
    for case, setup in CASES.items():
        name = setup["machine"]
        repro, mc, ident = run(case, args.machines, args.seed)
        paper = setup["paper"]
        print(f"\n== {name}: K = {setup['stiffness']:g} {setup['stiffness_unit']} per actuator, "
              f"load F = {list(LOAD_N)} N on the tool, tracker σ = {TRACKER_STD} mm")
        print(f"reproduction (paper's identified errors as the real machine): held-out max before "
              f"{repro['max_before_mm']:.3f} mm (paper {paper['max_before_mm']:.3f})")
        print(f"{'method':<20}{'improvement %':>14}{'max after mm':>14}   paper: {paper['improvement_pct']}%, "
              f"{paper['max_after_mm']} mm")
        for m in METHODS:
            r = repro[m]
            print(f"{m:<20}{r['improvement_pct']:>14.1f}{r['max_after_mm']:>14.4f}   rank {r['rank']}/{r['n_free']}")
        print("identified errors (reproduction, projection): parameter, paper (= simulated truth), "
              "truth in our gauge, ours ± 1σ")
        for pname, paper_v, true, est, sd, unit in ident:
            print(f"  {pname:<10}{paper_v:>9.3f}{true:>9.3f}{est:>9.3f} ± {sd:.3f} {unit}")
        print(f"Monte Carlo, {mc['machines']} machines ({mc['seconds_per_machine']:.2f} s each): "
              f"mean max before {mc['max_before_mm_mean']:.3f} mm")
        for m in METHODS:
            r = mc[m]
            print(f"{m:<20} improvement mean {r['improvement_mean_pct']:6.1f} %  worst {r['improvement_worst_pct']:6.1f} %"
                  f"   max after mean {r['max_after_mm_mean']:.4f} mm  worst {r['max_after_mm_worst']:.4f} mm")
        naive = max(("ignore-redundancy", "actuator-subset"), key=lambda m: mc[m]["improvement_mean_pct"])
        out[name] = {
            "projection_improvement_pct": round(mc["projection"]["improvement_mean_pct"], 2),
            "naive_improvement_pct": round(mc[naive]["improvement_mean_pct"], 2),
            "naive_method": naive,
            "max_before_mm": round(mc["max_before_mm_mean"], 4),
            "max_after_mm": round(mc["projection"]["max_after_mm_mean"], 4),
            "reproduction": {"projection_improvement_pct": round(repro["projection"]["improvement_pct"], 2),
                             "max_before_mm": round(repro["max_before_mm"], 4),
                             "max_after_mm": round(repro["projection"]["max_after_mm"], 4),
                             "paper": paper},
            "stiffness": f"{setup['stiffness']:g} {setup['stiffness_unit']}",
            "load_N": list(LOAD_N),
            "machines": mc["machines"],
        }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
