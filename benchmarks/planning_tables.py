"""Paper 2 Tables 1–2 with our numbers: observability indices of random and optimally
selected pose sets of 14, 28, …, 112 poses (paper 2's prototype, 3 dial indicators).

A thin wrapper of the reproduction ``paper2-tables1-2``
(:func:`pkmcal.reproduce.paper2_planning.paper2_tables1_2`, also ``pkmcal reproduce
paper2-tables1-2``): prints its table, then the markdown table of docs/planning.md
(paper, paper-like Jacobian, planning Jacobian; random and optimal). Last line: one JSON
object, per size n the four columns of O1..O4 (``--quick``: the reproduction's quick mode, 3
random sets per size instead of 10 and 400 candidates instead of 2,000; key ``quick``).

    python benchmarks/planning_tables.py [--seed 0] [--random-sets 10] [--quick]
"""

from __future__ import annotations

import argparse
import json
import sys

from _quick import parse_args  # benchmarks/_quick.py
from pkmcal.planning.indices import INDEX_NAMES
from pkmcal.reproduce.paper2_planning import PAPER_INDICES, SIZES, paper2_tables1_2


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--random-sets", type=int, default=None)
    args = parse_args(ap, argv, also="the reproduction's quick mode")
    r = paper2_tables1_2(seed=args.seed, quick=args.quick, random_sets=args.random_sets)
    print(r.format())
    out = {}
    for n in SIZES:
        g = f"{n} poses"
        row = {k: {s: r.row(f"{k} {s}", g) for s in ("random", "optimal")} for k in PAPER_INDICES}
        out[str(n)] = {
            "paper_random": [row[k]["random"].paper for k in PAPER_INDICES],
            "paper_optimal": [row[k]["optimal"].paper for k in PAPER_INDICES],
            "paper_like_random": {k: row[k]["random"].ours for k in PAPER_INDICES},
            "paper_like_optimal": {k: row[k]["optimal"].ours for k in PAPER_INDICES},
            "ours_random": {k: r.row(f"{k} random, planning J", g).ours for k in INDEX_NAMES},
            "ours_optimal": {k: r.row(f"{k} optimal, planning J", g).ours for k in INDEX_NAMES},
        }
    print("\n| n | index | paper random | paper optimal | paper-like random | paper-like optimal | ours random | ours optimal |")
    print("|---|---|---|---|---|---|---|---|")
    for n in SIZES:
        o = out[str(n)]
        for i, k in enumerate(PAPER_INDICES):
            print(f"| {n} | {k} | {o['paper_random'][i]:.3e} | {o['paper_optimal'][i]:.3e} | "
                  f"{o['paper_like_random'][k]:.3e} | {o['paper_like_optimal'][k]:.3e} | "
                  f"{o['ours_random'][k]:.3e} | {o['ours_optimal'][k]:.3e} |")
    out["seconds"] = round(r.seconds, 2)
    out["quick"] = args.quick
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main(sys.argv[1:])
