"""All paper reproductions (:mod:`pkmcal.reproduce`) in full mode: each table, ours beside
the paper's, with its setup and notes; the last line is one JSON object of the headline
numbers (and the seconds each took).

Usage: ``python benchmarks/reproduce_papers.py [--seed 0] [--quick] [--only NAME ...]``
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from _quick import parse_args  # benchmarks/_quick.py
from pkmcal.reproduce import REPRODUCTIONS, run_reproduction


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", nargs="*", default=list(REPRODUCTIONS))
    args = parse_args(ap, also="each reproduction's quick mode")
    out: dict = {"seed": args.seed, "quick": args.quick, "cores": os.cpu_count()}
    for name in args.only:
        r = run_reproduction(name, seed=args.seed, quick=args.quick)
        print("=" * 100)
        print(r.format())
        print()
        out[name] = dict(r.headline, seconds=round(r.seconds, 2))
    sys.stdout.flush()
    print(json.dumps(out))


if __name__ == "__main__":
    main()
