"""Monte Carlo: does calibrating from planned poses beat random and corner poses of the same count?

For each trial: a "real" machine = paper 2's prototype (legs 30 mm thick, see
:func:`test_machine`) with U(−e, e) errors (e = 1 mm) on
every identifiable parameter (the gauge parameters the engine fixes keep their nominal
values, so estimated and true parameters are comparable); N poses chosen by each strategy
(``default`` D-optimal plan from 2,000 random candidates, ``random`` from the same
candidates, ``corners`` = random corners of the largest all-reachable box, paper 1);
a simulated campaign (:func:`~pkmcal.identification.simulation.simulate_campaign`, the
setup's noise, seeded); identification with the engine (:func:`~pkmcal.identification.
engine.identify`, the setup's default method). Reported per setup and strategy: mean and
RMS of the parameter errors |ρ̂ − ρ_real| over the identifiable parameters, and the RMS /
max position error on 300 held-out random poses (commanded through the calibrated model,
reached by the real machine). Last line: one JSON object.

    python benchmarks/planning_montecarlo.py [--trials 10] [--n 30] [--seed 0] [--quick]

``--quick``: one trial per setup (the same setups, strategies and pose count; key ``quick``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace

import numpy as np

from _quick import parse_args  # benchmarks/_quick.py
from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.blocks import planning_model
from pkmcal.planning.candidates import corner_box, corner_poses, generate_candidates, workspace_box
from pkmcal.planning.error_maps import pose_errors
from pkmcal.planning.selection import select_default, select_random


def test_machine():
    """Paper 2's prototype with 30 mm legs instead of 36.1 mm: at home its paired legs clear
    each other by only 0.13 mm, so with 1 mm parameter errors the simulated real machine
    reports a leg collision at nearly every pose and no campaign can be simulated."""
    m = stewart_prototype()
    return replace(m, name="stewart-prototype-30mm-legs", limits=replace(m.limits, leg_diameter=30.0))


def run_setup(setup_name: str, trials: int, n: int, seed: int, magnitude: float) -> dict:
    nominal = test_machine()
    setup = load_setup(setup_name)
    model = planning_model(nominal, setup)
    names = list(nominal.param_names)
    ident = [names.index(nm) for nm in model.names if nm in names]
    box = workspace_box(nominal, setup)
    corners = corner_poses(corner_box(nominal, box, setup))
    rng = np.random.default_rng(seed)
    out = {s: {"param_mean": [], "param_rms": [], "held_rms": [], "held_max": [], "fit_failures": 0}
           for s in ("default", "random", "corners")}
    for t in range(trials):
        delta = np.zeros(len(names))
        delta[ident] = rng.uniform(-magnitude, magnitude, len(ident))
        real = nominal.with_params(nominal.params + delta, name="real")
        cand = generate_candidates(nominal, setup, n=2000, rng=rng, box=box)
        G, _ = model.blocks(cand.poses)
        plans = {
            "default": cand.poses[select_default(G, n).chosen],
            "random": cand.poses[select_random(len(cand.poses), n, rng)],
            "corners": corners[rng.choice(len(corners), size=n, replace=False)],
        }
        held = generate_candidates(nominal, setup, n=300, rng=rng, box=box).poses
        for strategy, poses in plans.items():
            sim = simulate_campaign(nominal, real, setup, poses, rng=rng)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    res = identify(nominal, setup, q=sim.actuator_readings, y=sim.sensor_readings,
                                   commanded=sim.commanded[sim.kept], method=model.method)
            except Exception as exc:  # a failed fit counts, it is not hidden
                out[strategy]["fit_failures"] += 1
                print(f"  trial {t} {strategy}: fit failed: {exc}")
                continue
            est = res.mechanism.params
            err = np.abs(est[ident] - real.params[ident])
            e_p, _ = pose_errors(res.mechanism, real, held)
            e_p = e_p[np.isfinite(e_p)]
            o = out[strategy]
            o["param_mean"].append(float(err.mean()))
            o["param_rms"].append(float(np.sqrt(np.mean(err**2))))
            o["held_rms"].append(float(np.sqrt(np.mean(e_p**2))))
            o["held_max"].append(float(e_p.max()))
    summary = {}
    for strategy, o in out.items():
        summary[strategy] = {k: (float(np.mean(v)) if isinstance(v, list) and v else v) for k, v in o.items()}
    summary["identifiable_parameters"] = len(ident)
    summary["method"] = model.method
    return summary


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=10)
    ap.add_argument("--n", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--magnitude", type=float, default=1.0)
    ap.add_argument("--setups", default="full-pose-paper1,indicators-prototype")
    args = parse_args(ap, argv, trials=1)
    t0 = time.perf_counter()
    result = {"trials": args.trials, "n_poses": args.n, "magnitude_mm": args.magnitude, "setups": {},
              "quick": args.quick}
    for name in args.setups.split(","):
        s = run_setup(name, args.trials, args.n, args.seed, args.magnitude)
        result["setups"][name] = s
        print(f"\n{name} ({s['method']}, {s['identifiable_parameters']} identifiable parameters), "
              f"{args.trials} trials, {args.n} poses, parameter errors U(±{args.magnitude:g} mm):")
        print(f"  {'strategy':<9} {'param mean':>11} {'param RMS':>10} {'held-out RMS':>13} {'held-out max':>13}  (mm)")
        for strategy in ("default", "random", "corners"):
            r = s[strategy]
            print(f"  {strategy:<9} {r['param_mean']:11.4g} {r['param_rms']:10.4g} {r['held_rms']:13.4g} "
                  f"{r['held_max']:13.4g}" + (f"  ({r['fit_failures']} failed fits)" if r["fit_failures"] else ""))
    result["elapsed_s"] = time.perf_counter() - t0
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
