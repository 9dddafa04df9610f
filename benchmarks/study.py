"""Study throughput: trials per second on one worker and on all local cores (issue 14).

Workload: ``examples/study-paper1.yaml`` — paper 1's set-up (42 parameters with
U(−5, 5) mm errors drawn per trial, a full-pose sensor with paper 1's uniform noise, 15
corners of the workspace box drawn per trial, ``ik-residual`` Levenberg–Marquardt, 10
held-out poses) on ``reproduce/paper1.py``'s machine-tool hexapod. Every trial is the whole
pipeline: draw the real machine, select the poses (plan), simulate, identify, verify; the
candidate pool (the box corners) and the held-out poses are planned once per study, as
``pkmcal study`` does (the table says so in ``plan_resampled``).

Measured: ``pkmcal.study.run_study`` into a fresh folder, figures off, once with
``workers=1`` (in this process) and once with all local cores (process pool); trials per
second = trials run / wall time of the run phase (pilot + backend, as ``run.json``'s
``run_seconds``; planning the pool before and writing the tables after excluded and
reported separately). ``parallel_efficiency`` = (all-local speed-up) / cores. Both runs
must give byte-identical ``trials.csv`` (checked, ``identical``). The 1-worker CPU time
per trial is also reported (``cpu_ms_per_trial_1worker``, and the trials per second one
core would run at it, ``trials_per_s_1core_from_cpu``), and the CPU of the all-local run
(this process and its workers, ``cpu_ms_per_trial_all_local``): on a machine shared with
other jobs the wall figures fall, the CPU figures much less, and their ratio
``cpu_efficiency_all_local`` = CPU(1 worker) / CPU(all local) is the parallel efficiency
the machine would show with its cores to itself (what forking, pickling and the part
files cost; 1 = nothing). ``load_average_before``: the 1-minute load average at the start.

Also timed (``--default-trials``, 0 to skip): ``examples/study-default.yaml`` (the default
machine, 10,000 trials) end to end on all local cores, figures included, as the issue's
"10,000-trial study of the default machine in under a minute" (``default_study_seconds``;
``default_study_cpu_seconds`` the CPU of this process and its workers: divided by the cores,
the wall time the machine would take with its cores to itself).

Usage: ``python benchmarks/study.py [--trials 2000] [--default-trials 10000] [--quick]``
(``--quick``: 4 trials of each study, still on one worker and on all local cores, figures
included; key ``quick``); the last line of output is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "src"))

from _quick import parse_args  # noqa: E402
from kinematics import cpu_model  # noqa: E402

from pkmcal import __version__  # noqa: E402
from pkmcal.study import load_study, run_study  # noqa: E402
from pkmcal.study.backends import local_cores  # noqa: E402


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the pool's workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def _run(study, workers, figures=False):
    tmp = Path(tempfile.mkdtemp(prefix="pkmcal-bench-study-"))
    try:
        c0 = _cpu()
        res = run_study(study, tmp / "r", workers=workers, figures=figures)
        cpu = _cpu() - c0
        data = (tmp / "r" / "trials.csv").read_bytes()
        return res, cpu, data
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=2000)
    ap.add_argument("--default-trials", type=int, default=10000)
    args = parse_args(ap, argv, trials=4, default_trials=4)
    cores = local_cores()
    load0 = os.getloadavg()[0]
    print(f"machine: {cpu_model()}, {cores} cores, {platform.python_implementation()} {platform.python_version()}, "
          f"pkmcal {__version__}, load average before {os.getloadavg()}")
    study = load_study(HERE.parent / "examples" / "study-paper1.yaml").with_trials(args.trials)
    _run(study.with_trials(2), 1)                          # warm-up: numba cache, imports
    one, cpu1, bytes1 = _run(study, 1)
    tps1 = one.trials_run / one.run_seconds
    print(f"1 worker: {one.trials_run} trials in {one.run_seconds:.2f} s run phase ({one.seconds:.2f} s total): "
          f"{tps1:.1f} trials/s; CPU {1e3 * cpu1 / one.trials_run:.2f} ms per trial (whole call)")
    alll, cpu_all, bytes_all = _run(study, None)
    tps_all = alll.trials_run / alll.run_seconds
    eff = tps_all / tps1 / cores
    print(f"all local ({alll.workers} workers, {alll.backend}): {alll.trials_run} trials in {alll.run_seconds:.2f} s "
          f"run phase ({alll.seconds:.2f} s total): {tps_all:.1f} trials/s; speed-up {tps_all / tps1:.2f}, "
          f"parallel efficiency {eff:.2f}; CPU {1e3 * cpu_all / alll.trials_run:.2f} ms per trial "
          f"(this process and the workers, whole call): CPU efficiency {cpu1 / cpu_all:.2f}")
    identical = bytes1 == bytes_all
    print(f"trials.csv identical for 1 and {alll.workers} workers: {identical}")
    out = {"trials_per_s_1worker": tps1, "trials_per_s_all_local": tps_all, "parallel_efficiency": eff,
           "cores": cores, "trials": args.trials, "cpu_ms_per_trial_1worker": 1e3 * cpu1 / one.trials_run,
           "trials_per_s_1core_from_cpu": one.trials_run / cpu1,
           "cpu_ms_per_trial_all_local": 1e3 * cpu_all / alll.trials_run,
           "cpu_efficiency_all_local": cpu1 / cpu_all, "identical": identical,
           "load_average_before": load0, "quick": args.quick}
    if args.default_trials:
        d = load_study(HERE.parent / "examples" / "study-default.yaml").with_trials(args.default_trials)
        t0 = time.perf_counter()
        res, cpu_d, _ = _run(d, None, figures=True)
        wall = time.perf_counter() - t0
        print(f"default machine study: {res.trials_run} trials end to end (plan, run, tables, figures, page) in "
              f"{wall:.1f} s on {res.workers} workers ({res.trials_run / res.run_seconds:.1f} trials/s in the run phase); "
              f"CPU {cpu_d:.1f} s (this process and the workers), {cpu_d / res.workers:.1f} s per core")
        out.update(default_study_trials=res.trials_run, default_study_seconds=wall, default_study_cpu_seconds=cpu_d)
    print(f"load average after {os.getloadavg()}")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
