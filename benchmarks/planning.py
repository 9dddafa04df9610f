"""Benchmark of pose selection (issue 4): time and O1/O4 of the default D-optimal exchange
choosing 30 of 2,000 and 110 of 10,000 candidates, and of paper 2's cuckoo search on the
first case, measured in the same run.

    python benchmarks/planning.py [--setup indicators-prototype] [--seed 0]

Machine: paper 2's prototype (``stewart-prototype``); candidates: random reachable and
measurable poses of its workspace box (seeded). The per-pose Jacobian blocks are computed
once (not timed); the timings are of the selection alone, after a warm-up call that
compiles the numba kernel. Wall and process CPU times are both reported: the planning code
runs single-threaded, so on a machine shared with other jobs the CPU time is the better
estimate of the unloaded wall time. Last line of output: one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time

import numpy as np

from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.blocks import planning_model
from pkmcal.planning.candidates import generate_candidates
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.selection import select_cuckoo, select_default, select_random


CPU = {}


def timed(fn, *args, **kwargs):
    """(result, wall seconds); the process CPU seconds go to CPU[id(result)]: the planning
    code is single-threaded, so on a loaded machine CPU time ≈ the unloaded wall time."""
    t, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    CPU[id(out)] = time.process_time() - c
    return out, time.perf_counter() - t


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--setup", default="indicators-prototype")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)

    machine = stewart_prototype()
    setup = load_setup(args.setup)
    model = planning_model(machine, setup)
    cand = generate_candidates(machine, setup, kind="random", n=10_000, rng=np.random.default_rng(args.seed))
    G, ok = model.blocks(cand.poses)
    if not ok.all():
        raise SystemExit("some candidate poses could not be solved at the nominal machine")
    G2000, X2000 = G[:2000], cand.poses[:2000]

    _, t_warm = timed(select_default, G[:200], 20)                       # numba compile / cache load
    d30, t_d30 = timed(select_default, G2000, 30)
    d110, t_d110 = timed(select_default, G, 110)
    c30, t_c30 = timed(select_cuckoo, G2000, 30, positions=X2000, index="O4", rng=np.random.default_rng(args.seed))
    c30_o1, t_c30_o1 = timed(select_cuckoo, G2000, 30, positions=X2000, index="O1",
                             rng=np.random.default_rng(args.seed))
    d30_o4, t_d30_o4 = timed(select_default, G2000, 30, index="O4")
    rng = np.random.default_rng(args.seed + 1)
    r30 = [observability_indices(G2000, select_random(2000, 30, rng)) for _ in range(20)]

    runs = [("default_30_of_2000", "default (D-optimal)", "30 of 2000", t_d30, d30),
            ("default_110_of_10000", "default (D-optimal)", "110 of 10000", t_d110, d110),
            ("cuckoo_30_of_2000", "cuckoo on O4 (paper 2)", "30 of 2000", t_c30, c30),
            ("cuckoo_O1_30_of_2000", "cuckoo on O1", "30 of 2000", t_c30_o1, c30_o1),
            ("default_O4_30_of_2000", "default --index O4", "30 of 2000", t_d30_o4, d30_o4)]
    result = {"setup": args.setup, "identifiable_parameters": model.n_params, "rows_per_pose": int(G.shape[1])}
    for key, _, _, t, sel in runs:
        result.update({f"{key}_s": t, f"{key}_cpu_s": CPU[id(sel)], f"{key}_O1": sel.indices["O1"],
                       f"{key}_O4": sel.indices["O4"]})
    result.update({
        "random_30_of_2000_mean_O1": float(np.mean([r["O1"] for r in r30])),
        "random_30_of_2000_mean_O4": float(np.mean([r["O4"] for r in r30])),
        "warmup_s": t_warm,
        "load_average_1min": os.getloadavg()[0],
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
    })
    print(f"machine stewart-prototype, setup {args.setup}: {model.n_params} identifiable parameters, "
          f"{G.shape[1]} rows per pose; {len(cand.poses)} candidates ({cand.describe()})")
    print(f"warm-up (numba compile or cache load): {t_warm:.3f} s; load average {result['load_average_1min']:.2f} "
          f"on {result['cores']} cores")
    for _, name, case, t, sel in runs:
        print(f"{name:<24} {case:<13} {t:8.3f} s ({CPU[id(sel)]:.3f} s CPU)   O1 = {sel.indices['O1']:.5g}   O4 = {sel.indices['O4']:.5g}   "
              f"({sel.message})")
    print(f"{'random (mean of 20)':<24} {'30 of 2000':<13} {'':>10}   O1 = {result['random_30_of_2000_mean_O1']:.5g}   "
          f"O4 = {result['random_30_of_2000_mean_O4']:.5g}")
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
