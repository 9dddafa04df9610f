"""Every benchmark runs (``benchmarks/*.py --quick``, issue 24 item 3).

Each script in ``benchmarks/`` is run as a user runs it, in a fresh process with this
interpreter and the pkmcal under test first on PYTHONPATH, with ``--quick`` and otherwise its
default arguments: it exits 0, its last line is one JSON object, and that object holds the
keys its docstring promises, numbers finite. The full runs stay manual (minutes each, and
their figures are the benchmarks' business, not a test's); no timing is checked here.

What a quick mode must not skip (``benchmarks/_quick.py``): any section that writes a key (a
key missing, or null where the full run writes a number, fails below), any setup, machine,
method or reproduction of the full run (the nested keys name them), and the correctness
checks the benchmarks make of their own results (the study's 1-worker and all-core
``trials.csv`` byte-identical, asserted here; the kinematics benchmark's C reference against
pkmcal, asserted inside it). It may only shrink sizes and repeats, and keeps each size on the
side of the thresholds where the measured code changes path (its docstring says which).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import pkmcal_subprocess_env

from pkmcal.reproduce import REPRODUCTIONS
from pkmcal.reproduce.paper2_planning import SIZES
from pkmcal.reproduce.paper3 import CASES

BENCHMARKS = Path(__file__).resolve().parent.parent / "benchmarks"


def _each(prefixes, names):
    return [(*p, n) if isinstance(p, tuple) else (p, n) for p in prefixes for n in names]


_FIT_FIGURES = ("ms", "fd_ms", "wall_ms", "fd_wall_ms", "solve_ms", "fd_solve_ms", "speedup", "solver_only_ms",
                "residual_us", "jacobian_us", "fd_jacobian_us", "jacobian_speedup", "speedup_bound")
_SELECTIONS = ("default_30_of_2000", "default_110_of_10000", "cuckoo_30_of_2000", "cuckoo_O1_30_of_2000",
               "default_O4_30_of_2000")
_PLANS = ("plan_110_of_100000", "plan_110_of_1000000")
_DELTA_HOWS = ("nominal", "klipper", "pkmcal_default", "pkmcal_refit", "pkmcal_prior", "klipper_object",
               "pkmcal_object")
_DELTA_LEAN_HOWS = ("nominal", "klipper", "klipper_rods", "pkmcal_prior", "klipper_block", "pkmcal_block",
                    "pkmcal_block_full", "volume_fit", "klipper_block_norods", "pkmcal_block_norods")
_DELTA_RADII_HOWS = ("nominal", "klipper", "pkmcal_default", "pkmcal_prior")
_DELTA_OBJECT_HOWS = ("nominal", "klipper_object", "pkmcal_object", "pkmcal_object_rods", "klipper_object_rings",
                      "pkmcal_object_rings", "pkmcal_object_rings_rods")
_DELTA_BOUNDS = ("object", "object_pkmcal_model", "object_klipper_weights", "object_rods", "object_rods_tolerance",
                 "object_rings", "object_rings_klipper_weights", "object_rings_rods", "object_heights_exact",
                 "object_distances_exact")
_MC_SETUPS = ("full-pose-paper1", "indicators-prototype")

#: Per benchmark: the keys (paths into the JSON object) its docstring promises.
PROMISED: dict[str, list[tuple[str, ...]]] = {
    "cli_startup": [(k,) for k in ("python_s", "help_s", "machines_s", "ik_10_s", "help_median_s",
                                   "machines_median_s", "ik_10_median_s")]
    + _each([("imports", c) for c in ("help", "machines", "ik_10")], ("heavy_s", "slowest_top_level_s")),
    "delta_vs_firmware": [(k,) for k in ("printers", "seed", "probe_points", "grid_points", "seconds")]
    + _each([(s, h) for s in ("no_leans", "leans") for h in _DELTA_HOWS],
            ("rms3d_median_mm", "rms3d_worst_mm", "first_layer_median_mm", "first_layer_worst_mm", "solve_s_median",
             "failures", "refused_then_accepted"))
    + _each([(s, h) for s in ("no_leans", "leans") for h in _DELTA_HOWS[2:] if h != "klipper_object"],
            ("worse_than_klipper", "improvement_over_klipper_pct"))
    + _each([("leans_block", h) for h in _DELTA_LEAN_HOWS] + [("unequal_radii", h) for h in _DELTA_RADII_HOWS],
            ("rms3d_median_mm", "rms3d_worst_mm", "first_layer_median_mm", "first_layer_worst_mm", "solve_s_median",
             "failures", "refused_then_accepted"))
    + _each([("leans_block", h) for h in ("pkmcal_prior", "pkmcal_block", "pkmcal_block_full", "volume_fit",
                                          "pkmcal_block_norods")]
            + [("unequal_radii", h) for h in ("pkmcal_default", "pkmcal_prior")],
            ("worse_than_klipper", "improvement_over_klipper_pct"))
    + [("leans_block", "lean_error_rms_deg_median"), ("leans_block", "true_lean_rms_deg_median")]
    + _each([("printed_object", h) for h in _DELTA_OBJECT_HOWS],
            ("rms3d_median_mm", "rms3d_worst_mm", "first_layer_median_mm", "first_layer_worst_mm", "solve_s_median",
             "failures", "refused_then_accepted"))
    + _each([("printed_object", h) for h in _DELTA_OBJECT_HOWS[2:]],
            ("worse_than_klipper", "improvement_over_klipper_pct"))
    + _each([("printed_object", "bound", b) for b in _DELTA_BOUNDS],
            ("rms3d_expected_median_mm", "rms3d_predicted_median_mm")),
    "identification": [(f"{fit}_{f}",) for fit in ("ik_residual", "fk_residual") for f in _FIT_FIGURES]
    + [(f"{fit}_problems",) for fit in ("ik_residual", "fk_residual")]
    + _each([("ik_residual_problems", 0), ("fk_residual_problems", 0)],
            ("nfev", "njev", "fd_nfev", "evaluations", "fd_evaluations", "max_estimate_difference_mm"))
    + [(k,) for k in ("efficiency_weighted", "efficiency_unweighted", "efficiency_rms_weighted",
                      "efficiency_rms_unweighted", "bound_rms_mm", "weighted_rms_mm", "unweighted_rms_mm",
                      "trials", "repeats", "problems", "fk_residual_poses")]
    + _each(["machine"], ("cpu", "cores", "load_average_1min", "load_average_1min_after")),
    "ik_memory": [(k,) for k in ("poses", "peak_rss_mb", "wall_s", "bytes_per_pose", "output_sha256")],
    "kinematics": [(k,) for k in ("n_poses", "ik_us_per_pose", "fk_us_per_pose", "fk_us_per_pose_1thread",
                                  "fk_mean_iterations", "fk_max_iterations", "fk_converged_fraction",
                                  "fk_not_converged", "fk_max_pose_error", "fk_loop_public_api_us_per_pose",
                                  "fk_loop_kernel_direct_us_per_pose", "loop_n", "c_reference_us_per_pose",
                                  "first_call_ik_s", "first_call_fk_s", "compile_ik_s", "compile_fk_s",
                                  "compile_s", "peak_rss_mb", "tracemalloc_peak_mb", "cpu", "cores",
                                  "numba_threads", "python", "numpy", "numba")],
    "planning": [(k,) for k in ("setup", "identifiable_parameters", "rows_per_pose", "warmup_s",
                                "random_30_of_2000_mean_O1", "random_30_of_2000_mean_O4", "python_start_s",
                                "numba_floor_s", "plan_8_of_100_s", "plan_8_of_100_poses",
                                "plan_110_of_100000_above_8_of_100_s", "plan_110_of_1000000_workers",
                                "plan_100000_candidates_tested", "check_limits_us_per_pose",
                                "check_limits_cpu_us_per_pose", "check_limits_numpy_us_per_pose",
                                "check_limits_numpy_cpu_us_per_pose", "load_average_1min", "cores", "cpu")]
    + [(f"{s}_{f}",) for s in _SELECTIONS for f in ("s", "cpu_s", "O1", "O4")]
    + [(f"{p}_{f}",) for p in _PLANS for f in ("s", "cpu_s", "peak_rss_mb")]
    + [(f"plan_100000_{stage}_{f}",) for stage in ("generate_check", "blocks", "select") for f in ("s", "cpu_s")],
    "planning_montecarlo": [(k,) for k in ("trials", "n_poses", "magnitude_mm", "elapsed_s")]
    + _each([("setups", s, strategy) for s in _MC_SETUPS for strategy in ("default", "random", "corners")],
            ("param_mean", "param_rms", "held_rms", "held_max", "fit_failures"))
    + _each([("setups", s) for s in _MC_SETUPS], ("identifiable_parameters", "method")),
    "planning_tables": [("seconds",)]
    + _each([str(n) for n in SIZES], ("paper_random", "paper_optimal", "paper_like_random", "paper_like_optimal",
                                      "ours_random", "ours_optimal")),
    "redundant": _each([c["machine"] for c in CASES.values()],
                       ("projection_improvement_pct", "naive_improvement_pct", "naive_method", "max_before_mm",
                        "max_after_mm", "machines"))
    + _each([(c["machine"], "reproduction") for c in CASES.values()],
            ("projection_improvement_pct", "max_before_mm", "max_after_mm", "paper")),
    "reproduce_papers": [("seed",), ("cores",)] + [(name, "seconds") for name in REPRODUCTIONS],
    "study": [(k,) for k in ("trials_per_s_1worker", "trials_per_s_all_local", "parallel_efficiency", "cores",
                             "trials", "cpu_ms_per_trial_1worker", "trials_per_s_1core_from_cpu",
                             "cpu_ms_per_trial_all_local", "cpu_efficiency_all_local", "identical",
                             "load_average_before", "default_study_trials", "default_study_seconds",
                             "default_study_cpu_seconds")],
}

#: Keys that are null by design in a run with default arguments: the 10^6 plan's worker count
#: when --workers is not given; the C reference where no C compiler is installed.
NULLABLE = {
    "planning": {("plan_110_of_1000000_workers",)},
    "kinematics": {("c_reference_us_per_pose",), ("c_reference_mean_iterations",),
                   ("c_reference_converged_fraction",)},
}


_MISSING = object()


def _lookup(obj, path):
    """The value at ``path`` (keys and list indices) in ``obj``, or _MISSING."""
    for part in path:
        if isinstance(part, int):
            if not isinstance(obj, list) or part >= len(obj):
                return _MISSING
        elif not isinstance(obj, dict) or part not in obj:
            return _MISSING
        obj = obj[part]
    return obj


def _not_finite(obj, path=()):
    """Paths of the numbers in ``obj`` that are NaN or infinite."""
    if isinstance(obj, dict):
        return [p for k, v in obj.items() for p in _not_finite(v, (*path, k))]
    if isinstance(obj, list):
        return [p for i, v in enumerate(obj) for p in _not_finite(v, (*path, i))]
    if isinstance(obj, float) and not math.isfinite(obj):
        return [path]
    return []


def test_every_benchmark_is_checked():
    scripts = {p.stem for p in BENCHMARKS.glob("*.py") if not p.name.startswith("_")}
    assert scripts == set(PROMISED), "a benchmark without its promised keys here, or keys of a removed one"


@pytest.mark.parametrize("name", sorted(PROMISED))
def test_quick_run(name, tmp_path):
    proc = subprocess.run([sys.executable, str(BENCHMARKS / f"{name}.py"), "--quick"], cwd=tmp_path,
                          env=pkmcal_subprocess_env(), capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"{name}.py --quick exited {proc.returncode}:\n{proc.stderr[-3000:]}"
    last = proc.stdout.rstrip("\n").splitlines()[-1]
    out = json.loads(last)
    assert isinstance(out, dict), f"{name}.py: the last line is not one JSON object: {last[:200]}"
    assert out.get("quick") is True, f"{name}.py: 'quick' is not true in its JSON"
    nullable = NULLABLE.get(name, set())
    missing = [p for p in PROMISED[name] if _lookup(out, p) is _MISSING]
    null = [p for p in PROMISED[name] if _lookup(out, p) is None and p not in nullable]
    assert not missing, f"{name}.py --quick: promised keys missing: {missing}"
    assert not null, f"{name}.py --quick: promised keys null: {null}"
    assert not _not_finite(out), f"{name}.py --quick: numbers not finite at {_not_finite(out)}"
    if name == "study":
        assert out["identical"] is True, "the study's trials.csv differs between 1 worker and all local cores"


def test_quick_defaults(monkeypatch):
    """``--quick`` changes the defaults it names, a value given on the command line wins, and
    a quick default for an argument the benchmark lacks is refused."""
    import argparse

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    from _quick import parse_args

    def parser():
        ap = argparse.ArgumentParser()
        ap.add_argument("--trials", type=int, default=1000)
        ap.add_argument("--seed", type=int, default=0)
        return ap

    full = parse_args(parser(), [], trials=3)
    assert (full.trials, full.seed, full.quick) == (1000, 0, False)
    quick = parse_args(parser(), ["--quick"], trials=3)
    assert (quick.trials, quick.seed, quick.quick) == (3, 0, True)
    given = parse_args(parser(), ["--trials", "7", "--quick"], trials=3)
    assert (given.trials, given.quick) == (7, True)
    with pytest.raises(ValueError, match="trails"):
        parse_args(parser(), ["--quick"], trails=3)


def test_delta_object_bound_is_what_a_weighted_fit_reaches(monkeypatch, tmp_path):
    """``delta_vs_firmware.object_bound`` (the Cramér–Rao bound of the printed-object set)
    against a referee it does not share: scipy's least_squares fitting Klipper's nine numbers
    to noisy readings weighted by their σ, each fit scored by the benchmark's own score (the
    true printer run by Klipper's DeltaCalibration). The mean of the scores' squares over the
    draws is the bound's expected square within 4 standard errors of that mean (measured: 1.0
    of them), and each draw's score is its linearised prediction within 1 % (measured 0.3 %:
    second-order terms, ~(0.05 mm)² / 200 mm against a 0.013 mm score). 60 draws know the mean
    square to 7 %: enough to catch a wrong σ or a Jacobian off by a factor, not the 6 %
    between the bound and Klipper's weighting (the last line, Gauss–Markov, checks that)."""
    pytest.importorskip("klippy.kinematics.delta")
    import shutil

    import numpy as np
    from scipy.optimize import least_squares

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import delta_vs_firmware as bench

    cfg = tmp_path / "printer.cfg"
    shutil.copy(bench.PRINTER_CFG, cfg)
    rng = np.random.default_rng(7)
    truth, _ = bench.random_truth(rng, False)
    _, _, block = bench.klipper_enhanced(str(cfg), truth, rng)
    grid = bench.volume_grid()[::5]
    bound = bench.object_bound(truth, block, np.zeros((0, 3)), grid, rng)
    heights, pairs = bench.saved_positions(block)
    v0 = bench.cfg_vector(bench.klipper_truth(truth))
    free = list(bench.KLIPPER_EXTENDED)
    sigma = np.r_[bench.height_sigmas(truth, heights), np.full(len(pairs), bench.CALIPER_OBJECT_STD)]
    exact = bench.firmware_readings(v0, heights, pairs)
    J = bench.central_jacobian(lambda v: bench.firmware_readings(v, heights, pairs), v0, free,
                               [bench.FD_STEP] * len(free))
    G = bench.central_jacobian(lambda v: bench.aligned_errors(
        bench.truth_at(truth, bench.klipper_calibration(bench.cfg_of_vector(v)), grid), grid).ravel(),
        v0, free, [bench.FD_STEP] * len(free))
    Jw = J / sigma[:, None]
    scores, predicted = [], []
    for _ in range(60):
        noise = rng.standard_normal(len(sigma)) * sigma
        y = exact + noise

        def residual(x):
            v = v0.copy()
            v[free] = x
            return (bench.firmware_readings(v, heights, pairs) - y) / sigma

        x = least_squares(residual, v0[free], x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12).x
        v = v0.copy()
        v[free] = x
        scores.append(bench.score(truth, bench.cfg_of_vector(v), grid)[0])
        dv = np.linalg.lstsq(Jw, noise / sigma, rcond=None)[0]
        predicted.append(math.sqrt(np.sum((G @ dv) ** 2) / len(grid)))
    scores, predicted = np.array(scores), np.array(predicted)
    assert np.max(np.abs(scores - predicted) / predicted) < 0.01
    expected = bound["object"][0] ** 2
    square = scores ** 2
    assert abs(square.mean() - expected) < 4.0 * square.std(ddof=1) / math.sqrt(len(square))
    assert bound["object"][0] < bound["object_klipper_weights"][0]       # Gauss–Markov
