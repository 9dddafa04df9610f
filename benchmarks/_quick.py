"""The ``--quick`` flag of every benchmark (a helper module, not a benchmark).

A benchmark's quick mode runs the same workload through the same code, at small sizes and
with few repeats, in seconds instead of minutes, so that CI can run every benchmark
(``tests/test_benchmarks.py``) and a broken benchmark is found the day it breaks, not the
day someone wants its figures. Its last line is the same JSON object with the same keys (the
full run's names, e.g. ``plan_110_of_100000_s``, even where the quick sizes are smaller)
plus ``"quick": true``: quick figures check that the benchmark runs, they are not its
figures and are never quoted.

What a quick mode may shrink: sizes (poses, candidates, trials, machines, problems) and
repeats. What it must keep: every section that writes a key, each size on the same side
of the thresholds where the code it measures changes path (a batch split over threads,
output written in blocks, candidates generated in chunks, the exchange's working-set cap),
and every setup and method of the full run.
"""

from __future__ import annotations

import argparse


def parse_args(ap: argparse.ArgumentParser, argv: list[str] | None = None, also: str = "",
               **quick) -> argparse.Namespace:
    """Add ``--quick`` to ``ap`` and parse ``argv``: under ``--quick`` the arguments named in
    ``quick`` (destinations) default to the values given there instead of their own
    defaults; a value given on the command line wins either way. ``also``: what else the
    benchmark shrinks under ``--quick`` (for its help)."""
    unknown = set(quick) - {a.dest for a in ap._actions}
    if unknown:
        raise ValueError(f"quick defaults for arguments the benchmark does not have: {sorted(unknown)}")
    parts = [", ".join(f"--{k.replace('_', '-')} {v}" for k, v in quick.items()) + " unless given"] if quick else []
    parts += [also] if also else []
    ap.add_argument("--quick", action="store_true",
                    help="seconds, not minutes: the same code at small sizes and few repeats"
                         + (f" ({'; '.join(parts)})" if parts else "")
                         + "; the JSON gets 'quick': true, its figures are not the benchmark's")
    pre = argparse.ArgumentParser(add_help=False)
    pre.add_argument("--quick", action="store_true")
    if pre.parse_known_args(argv)[0].quick:
        ap.set_defaults(**quick)
    return ap.parse_args(argv)
