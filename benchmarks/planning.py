"""Benchmark of pose planning: the selection (issue 4) and whole plans with large candidate
sets (issue 14 item 4), measured in the same run.

    python benchmarks/planning.py [--setup indicators-prototype] [--seed 0] [--skip-million]
                                  [--workers N] [--baseline-src DIR] [--repeat 3] [--quick]

Machine: paper 2's prototype (``stewart-prototype``); candidates: random reachable and
measurable poses of its workspace box (seeded).

* Selection: time and O1/O4 of the default D-optimal exchange choosing 30 of 2,000 and 110
  of 10,000 candidates, and of paper 2's cuckoo search on the first case. The per-pose
  Jacobian blocks are computed once (not timed); the timings are of the selection alone,
  after a warm-up call that compiles the numba kernel.
* Large candidate sets: ``pkmcal plan stewart-prototype --setup SETUP --n 110
  --n-candidates N`` end to end in a fresh process (start-up, imports, numba cache loads,
  candidates, blocks, selection, output file) for N = 100,000 (target ≤ 2 s) and N = 10^6
  (chunked, on ``--workers N`` processes when given; ``--skip-million`` to leave it out: its
  keys are then null), with the child's CPU time (its worker processes included) and peak
  resident memory (``os.wait4``'s ru_maxrss: the largest process); the 100,000 plan
  ``--repeat`` times (medians), alternated with the same command on the source tree
  ``--baseline-src DIR`` when given (e.g. the main branch's ``src``: before/after in one
  run, keys ``..._baseline_...``); beside them, the start-up floors of this machine
  (:func:`start_up_floors`: ``python -c pass`` and one cached numba function) and the plan
  of 8 of 100 candidates (of :func:`smallest_plan` poses: more when 8 poses' readings are
  fewer than the setup's identifiable parameters, 13 with the default three indicators;
  ``plan_8_of_100_poses``), whose difference from the 100,000 plan is that plan's own work
  (``plan_110_of_100000_above_8_of_100_s``: comparable between machines whose start-up
  differs); then, in this process, the
  stages of the 100,000 plan: candidate generation and checks (including the ~8× more poses
  tested than accepted), the planning blocks of the accepted candidates, and the selection;
  and the limit check per pose, compiled kernel (:meth:`Hexapod.check_limits` without
  margins, as the candidates use it) against the NumPy formulas it replaced.

Wall and process CPU times are both reported: on a machine shared with other jobs the CPU
time is the better estimate of the unloaded wall time (the checks use up to
``numba.get_num_threads()`` threads, so their CPU time can exceed their wall time). Last
line of output: one JSON object.

``--quick`` (:data:`QUICK`, key ``quick``; the keys keep the full run's sizes in their
names): one repeat, 12,000 candidates for the "100,000" plan (still above the exchange's
working-set threshold, max(10,000, 5 × the 2,200-candidate pool of 110 poses)), 60,000 for
the "10^6" plan (still in more than one chunk of ``CHUNK_SIZE``), 20,000 poses for the
limit check (still threaded), 2,400 / 600 candidates for the selections (110 poses still
chosen from a pre-selected pool of 2,200, 30 poses from all of them, as in the full run) and
at most 5 add/remove iterations of the cuckoo search (at most 10 × 30 in the full run,
which stopped after 22 on O4 and 33 on O1 with the default setup on 2026-12-03).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass

import numpy as np

from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.blocks import planning_model
from pkmcal.planning.candidates import CHUNK_SIZE, generate_candidates, random_poses, workspace_box
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.plan import candidate_blocks
from pkmcal.planning.selection import select, select_cuckoo, select_default, select_random

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _quick import parse_args  # noqa: E402  (benchmarks/_quick.py)
from kinematics import cpu_model  # noqa: E402  (benchmarks/kinematics.py)


@dataclass(frozen=True)
class Sizes:
    """Candidates and poses of each workload (the keys name the full run's)."""

    large: int = 100_000          # the "100,000" plan and its stages in this process
    million: int = 1_000_000      # the "10^6" plan
    limit_poses: int = 200_000    # poses of the per-pose limit check
    pool: int = 10_000            # candidates of the "110 of 10000" selection
    small_pool: int = 2_000       # candidates of the "30 of 2000" selections
    cuckoo_iterations: int | None = None    # add/remove iterations at most (None: select_cuckoo's 10 × poses)


FULL = Sizes()
QUICK = Sizes(large=12_000, million=CHUNK_SIZE + 10_000, limit_poses=20_000, pool=2_400, small_pool=600,
              cuckoo_iterations=5)


CPU = {}


def timed(fn, *args, **kwargs):
    """(result, wall seconds); the process CPU seconds go to CPU[id(result)]: the planning
    code is single-threaded, so on a loaded machine CPU time ≈ the unloaded wall time."""
    t, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    CPU[id(out)] = time.process_time() - c
    return out, time.perf_counter() - t


def run_child(n_candidates: int, setup: str, seed: int, workers: int | None = None, src: str | None = None,
              n: int = 110) -> dict:
    """``pkmcal plan --n-poses n`` in a fresh process (with ``--workers``; the package from ``src``
    when given): wall and CPU seconds, peak RSS (MB), its summary and the poses file's text. The
    command is given the old spelling ``--n``, which the trees of ``--baseline-src`` read too
    (``docs/options.md``)."""
    env = dict(os.environ) if src is None else {**os.environ, "PYTHONPATH": os.path.abspath(src)}
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "pkmcal.cli.main", "plan", "stewart-prototype", "--setup", setup, "--n", str(n),
               "--n-candidates", str(n_candidates), "--seed", str(seed), "-o", os.path.join(tmp, "poses.csv")]
        cmd += [] if workers is None else ["--workers", str(workers)]
        with open(os.path.join(tmp, "out.txt"), "w+") as out, open(os.path.join(tmp, "err.txt"), "w+") as err:
            t = time.perf_counter()
            proc = subprocess.Popen(cmd, stdout=out, stderr=err, env=env)
            _, status, usage = os.wait4(proc.pid, 0)
            wall = time.perf_counter() - t
            proc.returncode = os.waitstatus_to_exitcode(status)
            out.seek(0)
            err.seek(0)
            text, errors = out.read(), err.read()
            poses = open(os.path.join(tmp, "poses.csv")).read() if proc.returncode == 0 else ""
    if proc.returncode != 0:
        raise SystemExit(f"pkmcal plan --n-candidates {n_candidates} failed: {errors.strip()}")
    scale = 1.0 if sys.platform == "darwin" else 1024.0       # ru_maxrss: bytes on macOS, KiB on Linux
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
            "peak_rss_mb": usage.ru_maxrss * scale / 2**20, "summary": text.splitlines()[0], "poses": poses}


#: The least a process that calls one compiled (cached) numba function costs: the
#: interpreter, NumPy, numba and the lowering registries numba loads before its first call
#: (they import SciPy's linear algebra). Every compiled pkmcal command pays it.
NUMBA_FLOOR = """
import numba

@numba.njit(cache=True)
def one_more(x):
    return x + 1
"""


def start_up_floors(repeat: int) -> dict:
    """Wall seconds (medians of ``repeat`` fresh processes) of ``python -c pass`` and of
    :data:`NUMBA_FLOOR` calling its function, its numba cache filled first."""
    with tempfile.TemporaryDirectory() as tmp:
        with open(os.path.join(tmp, "floor.py"), "w") as f:
            f.write(NUMBA_FLOOR)
        env = {**os.environ, "NUMBA_CACHE_DIR": os.path.join(tmp, "cache")}
        commands = {"python_start_s": [sys.executable, "-c", "pass"],
                    "numba_floor_s": [sys.executable, "-c", "import floor; floor.one_more(1)"]}
        subprocess.run(commands["numba_floor_s"], cwd=tmp, env=env, check=True)       # fills the cache
        runs = {k: [] for k in commands}
        for _ in range(repeat):
            for key, cmd in commands.items():
                t = time.perf_counter()
                subprocess.run(cmd, cwd=tmp, env=env, check=True)
                runs[key].append(time.perf_counter() - t)
    return {k: float(np.median(v)) for k, v in runs.items()}


def timed_cpu(fn, *args, **kwargs):
    """(result, wall seconds, process CPU seconds)."""
    t, c = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - t, time.process_time() - c


def _median_runs(runs: list[dict]) -> dict:
    return {k: float(np.median([r[k] for r in runs])) for k in ("wall_s", "cpu_s", "peak_rss_mb")}


#: Poses of the small plan whose time is the start-up floor of a plan (8: enough readings for
#: the 42 parameters of a full-pose setup, 6 readings a pose).
SMALL_PLAN_POSES = 8


def smallest_plan(model) -> int:
    """:data:`SMALL_PLAN_POSES`, or the fewest poses whose readings cover the setup's
    identifiable parameters when 8 do not (``pkmcal plan`` refuses fewer: 13 for the three
    dial indicators, 3 readings a pose for 39 parameters)."""
    return max(SMALL_PLAN_POSES, -(-model.n_params // model.rows_per_pose))


def large_candidate_sets(setup_name: str, seed: int, skip_million: bool, workers: int | None = None,
                         baseline_src: str | None = None, repeat: int = 3, sizes: Sizes = FULL) -> dict:
    """Issue 14 item 4: whole plans with 10^5 and 10^6 candidates, the stages of the first,
    and the per-pose limit check (module docstring)."""
    machine = stewart_prototype()
    setup = load_setup(setup_name)
    model = planning_model(machine, setup)
    n_small = smallest_plan(model)
    res = start_up_floors(repeat)
    ours, base, tiny = [], [], []
    for _ in range(repeat):                       # alternated: both see the same load
        tiny.append(run_child(100, setup_name, seed, n=n_small))
        ours.append(run_child(sizes.large, setup_name, seed))
        if baseline_src is not None:
            base.append(run_child(sizes.large, setup_name, seed, src=baseline_src))
    for tag, runs in (("", ours), ("_baseline", base)):
        if not runs:
            continue
        med = _median_runs(runs)
        key = f"plan_110_of_100000{tag}"
        res.update({f"{key}_s": med["wall_s"], f"{key}_cpu_s": med["cpu_s"], f"{key}_peak_rss_mb": med["peak_rss_mb"]})
        print(f"pkmcal plan --n-poses 110 --n-candidates {sizes.large}"
              f"{' (baseline ' + baseline_src + ')' if tag else ''}, median "
              f"of {len(runs)}: {med['wall_s']:.2f} s wall, {med['cpu_s']:.2f} s CPU, peak RSS "
              f"{med['peak_rss_mb']:.0f} MB; {runs[0]['summary']}")
    res["plan_8_of_100_s"] = _median_runs(tiny)["wall_s"]
    res["plan_8_of_100_poses"] = n_small
    res["plan_110_of_100000_above_8_of_100_s"] = res["plan_110_of_100000_s"] - res["plan_8_of_100_s"]
    print(f"start-up floors, medians of {repeat}: python -c pass {res['python_start_s']:.2f} s; one cached numba "
          f"function {res['numba_floor_s']:.2f} s; pkmcal plan --n-poses {n_small} --n-candidates 100 "
          f"{res['plan_8_of_100_s']:.2f} s, "
          f"so the {sizes.large} plan's own work is {res['plan_110_of_100000_above_8_of_100_s']:.2f} s")
    if base:
        res["plan_110_of_100000_same_as_baseline"] = base[0]["poses"] == ours[0]["poses"]
        print(f"same poses file as the baseline: {res['plan_110_of_100000_same_as_baseline']}")
    key = "plan_110_of_1000000"
    res[f"{key}_workers"] = workers
    if skip_million:
        res.update({f"{key}_s": None, f"{key}_cpu_s": None, f"{key}_peak_rss_mb": None})
    else:
        child = run_child(sizes.million, setup_name, seed, workers=workers)
        res.update({f"{key}_s": child["wall_s"], f"{key}_cpu_s": child["cpu_s"],
                    f"{key}_peak_rss_mb": child["peak_rss_mb"]})
        print(f"pkmcal plan --n-poses 110 --n-candidates {sizes.million}{f' --workers {workers}' if workers else ''}: "
              f"{child['wall_s']:.2f} s wall, {child['cpu_s']:.2f} s CPU, peak RSS {child['peak_rss_mb']:.0f} MB; "
              f"{child['summary']}")
    box = workspace_box(machine, setup)
    generate_candidates(machine, setup, n=1000, rng=np.random.default_rng(seed), box=box)     # warm-up
    cand, t_gen, c_gen = timed_cpu(generate_candidates, machine, setup, n=sizes.large, box=box,
                                   rng=np.random.default_rng(seed))
    (G, ok), t_blk, c_blk = timed_cpu(candidate_blocks, model, cand.poses)
    sel, t_sel, c_sel = timed_cpu(select, G[ok], 110, rng=np.random.default_rng(seed), positions=cand.poses[ok])
    poses = random_poses(box, sizes.limit_poses, np.random.default_rng(seed + 1))
    machine.check_limits(poses[:10], margin=0.1, margins=False)
    _, t_ker, c_ker = timed_cpu(machine.check_limits, poses, margin=0.1, margins=False)
    _, t_np, c_np = timed_cpu(machine._limit_margins_numpy, poses, 0.1)
    res.update({
        "plan_100000_candidates_tested": cand.n_tested,
        "plan_100000_generate_check_s": t_gen, "plan_100000_generate_check_cpu_s": c_gen,
        "plan_100000_blocks_s": t_blk, "plan_100000_blocks_cpu_s": c_blk,
        "plan_100000_select_s": t_sel, "plan_100000_select_cpu_s": c_sel,
        "check_limits_us_per_pose": 1e6 * t_ker / len(poses), "check_limits_cpu_us_per_pose": 1e6 * c_ker / len(poses),
        "check_limits_numpy_us_per_pose": 1e6 * t_np / len(poses),
        "check_limits_numpy_cpu_us_per_pose": 1e6 * c_np / len(poses),
    })
    print(f"stages of the {sizes.large}-candidate plan (in process): candidates {t_gen:.3f} s ({c_gen:.3f} s CPU; "
          f"{cand.n_tested} poses tested), blocks {t_blk:.3f} s ({c_blk:.3f} s CPU), "
          f"selection {t_sel:.3f} s ({c_sel:.3f} s CPU)")
    print(f"limit check per pose: compiled {res['check_limits_us_per_pose']:.3f} µs "
          f"({res['check_limits_cpu_us_per_pose']:.3f} µs CPU), NumPy formulas "
          f"{res['check_limits_numpy_us_per_pose']:.3f} µs ({res['check_limits_numpy_cpu_us_per_pose']:.3f} µs CPU)")
    return res


def main(argv: list[str]) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--setup", default="indicators-prototype")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--skip-million", action="store_true", help="leave out the 10^6-candidate plan (keys null)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes of the 10^6-candidate plan")
    ap.add_argument("--baseline-src", default=None, help="also time the 100,000 plan with this source tree (alternated)")
    ap.add_argument("--repeat", type=int, default=3, help="runs of the 100,000 plan (medians)")
    args = parse_args(ap, argv, also="the sizes of QUICK (module docstring)", repeat=1)
    sizes = QUICK if args.quick else FULL
    large = large_candidate_sets(args.setup, args.seed, args.skip_million, args.workers, args.baseline_src,
                                 args.repeat, sizes)

    machine = stewart_prototype()
    setup = load_setup(args.setup)
    model = planning_model(machine, setup)
    cand = generate_candidates(machine, setup, kind="random", n=sizes.pool, rng=np.random.default_rng(args.seed))
    G, ok = model.blocks(cand.poses)
    if not ok.all():
        raise SystemExit("some candidate poses could not be solved at the nominal machine")
    G2000, X2000 = G[:sizes.small_pool], cand.poses[:sizes.small_pool]

    _, t_warm = timed(select_default, G[:200], 20)                       # numba compile / cache load
    d30, t_d30 = timed(select_default, G2000, 30)
    d110, t_d110 = timed(select_default, G, 110)
    c30, t_c30 = timed(select_cuckoo, G2000, 30, positions=X2000, index="O4", rng=np.random.default_rng(args.seed),
                       max_iter=sizes.cuckoo_iterations)
    c30_o1, t_c30_o1 = timed(select_cuckoo, G2000, 30, positions=X2000, index="O1",
                             rng=np.random.default_rng(args.seed), max_iter=sizes.cuckoo_iterations)
    d30_o4, t_d30_o4 = timed(select_default, G2000, 30, index="O4")
    rng = np.random.default_rng(args.seed + 1)
    r30 = [observability_indices(G2000, select_random(len(G2000), 30, rng)) for _ in range(20)]

    small, large_ = f"30 of {sizes.small_pool}", f"110 of {sizes.pool}"
    runs = [("default_30_of_2000", "default (D-optimal)", small, t_d30, d30),
            ("default_110_of_10000", "default (D-optimal)", large_, t_d110, d110),
            ("cuckoo_30_of_2000", "cuckoo on O4 (paper 2)", small, t_c30, c30),
            ("cuckoo_O1_30_of_2000", "cuckoo on O1", small, t_c30_o1, c30_o1),
            ("default_O4_30_of_2000", "default --index O4", small, t_d30_o4, d30_o4)]
    result = {"setup": args.setup, "identifiable_parameters": model.n_params, "rows_per_pose": int(G.shape[1])}
    for key, _, _, t, sel in runs:
        result.update({f"{key}_s": t, f"{key}_cpu_s": CPU[id(sel)], f"{key}_O1": sel.indices["O1"],
                       f"{key}_O4": sel.indices["O4"]})
    result.update({
        "random_30_of_2000_mean_O1": float(np.mean([r["O1"] for r in r30])),
        "random_30_of_2000_mean_O4": float(np.mean([r["O4"] for r in r30])),
        "warmup_s": t_warm,
        "quick": args.quick,
        "sizes": asdict(sizes),
        **large,
        "load_average_1min": os.getloadavg()[0],
        "cores": os.cpu_count(),
        "cpu": cpu_model(),
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
    print(f"{'random (mean of 20)':<24} {small:<13} {'':>10}   O1 = {result['random_30_of_2000_mean_O1']:.5g}   "
          f"O4 = {result['random_30_of_2000_mean_O4']:.5g}")
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
