"""Hexapod IK and FK throughput on ``stewart-prototype``.

Workload: 100,000 random poses, uniform in a box around the home pose (x, y ±30 mm,
z ±15 mm, roll/pitch/yaw ±20°); IK of every pose, then FK of the resulting leg lengths
cold-started from the home pose (the hard case: no previous pose to start from).

Reported: µs/pose (best of ``--repeats`` timed runs after a warm-up run, so numba's compile
and cache-load time is excluded and printed separately), numba's compile time with an empty
cache in a fresh process (``compile_s``, IK + FK), FK mean iterations, converged fraction
and non-converged count, peak memory, and the machine (CPU, cores, threads, versions). The
kernels are serial and split large batches over a Python thread pool of
``numba.get_num_threads()`` workers, so ``numba.set_num_threads(1)`` gives the one-thread
figures. Also a pose-by-pose loop through the public API (one
``Hexapod.fk`` call per pose) and the same kernel forced onto one thread, to put a
"faster than a compiled Newton solver called pose by pose" claim in context.

The last line of output is one JSON object.

Usage: ``python benchmarks/kinematics.py [--n 100000] [--repeats 15] [--seed 0] [--quick]``
(``--quick``: 10,000 poses, so that IK and FK are still split over threads, one repeat, 200
poses pose by pose; the compile in a fresh process stays: it is what ``compile_s`` measures;
key ``quick``)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import sys
import time
import tracemalloc

import numpy as np

from _quick import parse_args  # benchmarks/_quick.py

T_IMPORT = time.perf_counter()
import numba  # noqa: E402

from pkmcal.mechanisms import builtin_machine  # noqa: E402
from pkmcal.mechanisms import _hexapod_kernels as kernels  # noqa: E402

T_IMPORT = time.perf_counter() - T_IMPORT


# A plain C Newton FK (written for this benchmark, same algorithm as the pkmcal kernel minus
# the batch-level hoisting: twist Jacobian, LU with partial pivoting, R <- exp([dw]x) R, stop
# when max |L - L_target| <= tol), called once per pose from a C loop on one thread: what a
# "C Newton solver called pose by pose" costs without any Python overhead.
C_REFERENCE = r"""
#include <math.h>
static int solve6(double J[6][6], double r[6], double d[6]) {
    double scale = 0.0;
    for (int i = 0; i < 6; i++) for (int j = 0; j < 6; j++) if (fabs(J[i][j]) > scale) scale = fabs(J[i][j]);
    if (!(scale > 0.0)) return 0;
    for (int c = 0; c < 6; c++) {
        int piv = c; double best = fabs(J[c][c]);
        for (int i = c + 1; i < 6; i++) if (fabs(J[i][c]) > best) { best = fabs(J[i][c]); piv = i; }
        if (!(best > 1e-12 * scale)) return 0;
        if (piv != c) {
            for (int j = 0; j < 6; j++) { double t = J[c][j]; J[c][j] = J[piv][j]; J[piv][j] = t; }
            double t = r[c]; r[c] = r[piv]; r[piv] = t;
        }
        for (int i = c + 1; i < 6; i++) {
            double f = J[i][c] / J[c][c];
            for (int j = c; j < 6; j++) J[i][j] -= f * J[c][j];
            r[i] -= f * r[c];
        }
    }
    for (int i = 5; i >= 0; i--) {
        double s = r[i];
        for (int j = i + 1; j < 6; j++) s -= J[i][j] * d[j];
        d[i] = s / J[i][i];
    }
    return 1;
}
static void fk_one(const double *Lt, const double *g, const double *b, const double *a,
                   double tol, int max_iter, double *pose, int *conv, int *iters) {
    double ca = cos(g[3]), cb = cos(g[4]), cc = cos(g[5]), sa = sin(g[3]), sb = sin(g[4]), sc = sin(g[5]);
    double R[3][3] = {{cc*cb, cc*sb*sa - sc*ca, cc*sb*ca + sc*sa},
                      {sc*cb, sc*sb*sa + cc*ca, sc*sb*ca - cc*sa},
                      {-sb, cb*sa, cb*ca}};
    double p[3] = {g[0], g[1], g[2]}, J[6][6], r[6], d[6];
    int it = 0; *conv = 0;
    for (;;) {
        double err = 0.0;
        for (int i = 0; i < 6; i++) {
            double ra[3], l[3], s = 0.0;
            for (int k = 0; k < 3; k++) {
                ra[k] = R[k][0]*a[3*i] + R[k][1]*a[3*i+1] + R[k][2]*a[3*i+2];
                l[k] = p[k] + ra[k] - b[3*i+k];
                s += l[k]*l[k];
            }
            double L = sqrt(s);
            r[i] = Lt[i] - L;
            if (!(fabs(r[i]) <= err)) err = fabs(r[i]);
            for (int k = 0; k < 3; k++) J[i][k] = l[k] / L;
            J[i][3] = ra[1]*J[i][2] - ra[2]*J[i][1];
            J[i][4] = ra[2]*J[i][0] - ra[0]*J[i][2];
            J[i][5] = ra[0]*J[i][1] - ra[1]*J[i][0];
        }
        if (!isfinite(err)) break;
        if (err <= tol) { *conv = 1; break; }
        if (it >= max_iter || !solve6(J, r, d)) break;
        it++;
        for (int k = 0; k < 3; k++) p[k] += d[k];
        double th = sqrt(d[3]*d[3] + d[4]*d[4] + d[5]*d[5]);
        if (th > 0.0) {
            double kx = d[3]/th, ky = d[4]/th, kz = d[5]/th, ct = cos(th), st = sin(th), vt = 1.0 - ct;
            double E[3][3] = {{ct + kx*kx*vt, kx*ky*vt - kz*st, kx*kz*vt + ky*st},
                              {ky*kx*vt + kz*st, ct + ky*ky*vt, ky*kz*vt - kx*st},
                              {kz*kx*vt - ky*st, kz*ky*vt + kx*st, ct + kz*kz*vt}}, Rn[3][3];
            for (int i = 0; i < 3; i++) for (int j = 0; j < 3; j++)
                Rn[i][j] = E[i][0]*R[0][j] + E[i][1]*R[1][j] + E[i][2]*R[2][j];
            for (int i = 0; i < 3; i++) for (int j = 0; j < 3; j++) R[i][j] = Rn[i][j];
        }
    }
    *iters = it;
    pose[0] = p[0]; pose[1] = p[1]; pose[2] = p[2];
    pose[4] = -asin(fmax(-1.0, fmin(1.0, R[2][0])));
    pose[3] = atan2(R[2][1], R[2][2]);
    pose[5] = atan2(R[1][0], R[0][0]);
}
void fk_loop(int n, const double *L, const double *guess, const double *b, const double *a,
             double tol, int max_iter, double *poses, int *conv, int *iters) {
    for (int k = 0; k < n; k++)
        fk_one(L + 6*k, guess, b, a, tol, max_iter, poses + 6*k, conv + k, iters + k);
}
"""


def build_c_reference():
    """Compile :data:`C_REFERENCE` with the system C compiler (gcc -O2); None if unavailable."""
    import atexit
    import ctypes
    import shutil
    import subprocess
    import tempfile

    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None, "no C compiler"
    tmp = tempfile.mkdtemp(prefix="pkmcal-bench-")
    atexit.register(shutil.rmtree, tmp, True)       # the loaded library needs no file after dlopen
    src, lib = os.path.join(tmp, "fk.c"), os.path.join(tmp, "fk.so")
    with open(src, "w") as f:
        f.write(C_REFERENCE)
    cmd = [cc, "-O2", "-std=c99", "-fPIC", "-shared", src, "-o", lib, "-lm"]
    try:
        subprocess.run(cmd, check=True, capture_output=True)
    except (subprocess.CalledProcessError, OSError) as exc:
        return None, f"compile failed: {exc}"
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()[0]
    dll = ctypes.CDLL(lib)
    dp = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    ip = np.ctypeslib.ndpointer(dtype=np.int32, flags="C_CONTIGUOUS")
    dll.fk_loop.argtypes = [ctypes.c_int, dp, dp, dp, dp, ctypes.c_double, ctypes.c_int, dp, ip, ip]
    dll.fk_loop.restype = None
    return dll.fk_loop, f"{version}, {' '.join(cmd[1:4])}"


def random_poses(machine, n: int, rng: np.random.Generator) -> np.ndarray:
    half = np.array([30.0, 30.0, 15.0, *np.deg2rad([20.0, 20.0, 20.0])])
    return machine.home_pose + rng.uniform(-1.0, 1.0, (n, 6)) * half


def best_time(fn, repeats: int) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def compile_times() -> tuple[float, float]:
    """numba compile time of the IK and FK kernels (one serial kernel each), measured in a
    fresh interpreter with an empty, private NUMBA_CACHE_DIR so nothing is loaded from
    (or written to) the package's on-disk cache."""
    import subprocess
    import tempfile

    code = (
        "import time, numpy as np\n"
        "from pkmcal.mechanisms import builtin_machine\n"
        "m = builtin_machine('stewart-prototype')\n"
        "P1, P2 = np.tile(m.home_pose, (1, 1)), np.tile(m.home_pose, (100, 1))\n"
        "t0 = time.perf_counter(); L1 = m.leg_lengths(P1); L2 = m.leg_lengths(P2); t1 = time.perf_counter()\n"
        "m.fk_lengths(L1); m.fk_lengths(L2); t2 = time.perf_counter()\n"
        "print(t1 - t0, t2 - t1)\n"
    )
    with tempfile.TemporaryDirectory(prefix="pkmcal-numba-cache-") as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=tmp)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    t_ik, t_fk = (float(v) for v in out.stdout.split())
    return t_ik, t_fk


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--loop-n", type=int, default=2000, help="poses for the pose-by-pose loop")
    # quick: every batch still large enough to be split over threads (IK from 2 × its grain)
    args = parse_args(ap, argv, n=2 * kernels._IK_GRAIN, repeats=1, loop_n=200)

    machine = builtin_machine("stewart-prototype")
    rng = np.random.default_rng(args.seed)
    poses = random_poses(machine, args.n, rng)

    # -- compile / cache-load time (first call of each kernel) -------------------------
    t0 = time.perf_counter()
    lengths = machine.leg_lengths(poses[:10])
    t_ik_first = time.perf_counter() - t0
    t0 = time.perf_counter()
    machine.fk_lengths(lengths)
    t_fk_first = time.perf_counter() - t0
    # warm-up on the full size (thread pool start, page faults)
    lengths = machine.leg_lengths(poses)
    fk = machine.fk_lengths(lengths)
    t_ik_compile, t_fk_compile = compile_times()

    tracemalloc.start()
    t_ik = best_time(lambda: machine.leg_lengths(poses), args.repeats)
    t_fk = best_time(lambda: machine.fk_lengths(lengths), args.repeats)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    fk = machine.fk_lengths(lengths)
    pose_err = np.abs(fk.poses - poses)[fk.converged].max()

    # -- one thread: the same compiled Newton, no parallelism --------------------------
    n_threads = numba.get_num_threads()
    numba.set_num_threads(1)
    t_fk_1thread = best_time(lambda: machine.fk_lengths(lengths), max(1, args.repeats // 2))
    numba.set_num_threads(n_threads)

    # -- pose by pose through the public API -------------------------------------------
    m = min(args.loop_n, args.n)
    readings = lengths[:m] - machine.offset

    def loop():
        for k in range(m):
            machine.fk(readings[k])

    loop()
    t_loop = best_time(loop, 3)
    home = np.ascontiguousarray(np.broadcast_to(machine.home_pose, (1, 6)))
    rows = [np.ascontiguousarray(lengths[k : k + 1]) for k in range(m)]

    def loop_kernel():
        for k in range(m):
            kernels.fk_newton(rows[k], home, machine.base, machine.platform, 1e-9, 30)

    loop_kernel()
    t_loop_kernel = best_time(loop_kernel, 3)

    # -- the C reference, pose by pose on one thread ------------------------------------
    c_fk, c_info = build_c_reference()
    t_c = c_conv_frac = c_mean_it = None
    if c_fk is not None:
        c_poses = np.empty((args.n, 6))
        c_conv = np.empty(args.n, dtype=np.int32)
        c_it = np.empty(args.n, dtype=np.int32)
        L_c = np.ascontiguousarray(lengths)
        home_c = np.ascontiguousarray(machine.home_pose, dtype=float)
        b_c, a_c = np.ascontiguousarray(machine.base), np.ascontiguousarray(machine.platform)
        run_c = lambda: c_fk(args.n, L_c, home_c, b_c, a_c, 1e-9, 30, c_poses, c_conv, c_it)  # noqa: E731
        run_c()
        t_c = best_time(run_c, max(1, args.repeats // 2))
        c_conv_frac, c_mean_it = float(c_conv.mean()), float(c_it.mean())
        assert np.abs(c_poses - poses)[c_conv == 1].max() < 1e-7, "C reference disagrees with pkmcal"

    peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    us = lambda t, n: 1e6 * t / n  # noqa: E731
    result = {
        "machine": machine.name,
        "n_poses": args.n,
        "ik_us_per_pose": round(us(t_ik, args.n), 4),
        "fk_us_per_pose": round(us(t_fk, args.n), 4),
        "fk_us_per_pose_1thread": round(us(t_fk_1thread, args.n), 4),
        "fk_mean_iterations": round(float(fk.iterations.mean()), 4),
        "fk_max_iterations": int(fk.iterations.max()),
        "fk_converged_fraction": float(fk.converged.mean()),
        "fk_not_converged": int((~fk.converged).sum()),
        "fk_max_pose_error": float(pose_err),
        "fk_loop_public_api_us_per_pose": round(us(t_loop, m), 3),
        "fk_loop_kernel_direct_us_per_pose": round(us(t_loop_kernel, m), 3),
        "loop_n": m,
        "c_reference_us_per_pose": None if t_c is None else round(us(t_c, args.n), 4),
        "c_reference_mean_iterations": c_mean_it,
        "c_reference_converged_fraction": c_conv_frac,
        "c_reference_compiler": c_info,
        "first_call_ik_s": round(t_ik_first, 3),
        "first_call_fk_s": round(t_fk_first, 3),
        "compile_ik_s": round(t_ik_compile, 3),
        "compile_fk_s": round(t_fk_compile, 3),
        "compile_s": round(t_ik_compile + t_fk_compile, 3),
        "import_s": round(T_IMPORT, 3),
        "peak_rss_mb": round(peak_rss_mb, 1),
        "tracemalloc_peak_mb": round(traced_peak / 2**20, 2),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "numba_threads": n_threads,
        "threading_layer": numba.threading_layer(),
        "parallelism": "serial nogil kernels on a concurrent.futures thread pool",
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "quick": args.quick,
    }

    print(f"machine under test: {machine.name}; {args.n} random poses, home ± (30, 30, 15 mm, 20°, 20°, 20°)")
    print(f"host: {result['cpu']}, {result['cores']} cores, numba {numba.__version__} "
          f"({n_threads} threads, layer '{result['threading_layer']}'), numpy {np.__version__}, "
          f"Python {result['python']}")
    print(f"numba compile (fresh process, empty cache): IK {t_ik_compile:.3f} s, FK {t_fk_compile:.3f} s, "
          f"total {t_ik_compile + t_fk_compile:.3f} s; "
          f"first call in this process (cache load or compile): IK {t_ik_first:.3f} s, FK {t_fk_first:.3f} s")
    print(f"IK: {result['ik_us_per_pose']:.4f} µs/pose (best of {args.repeats})")
    print(f"FK (cold start from home): {result['fk_us_per_pose']:.4f} µs/pose, "
          f"{result['fk_us_per_pose_1thread']:.4f} µs/pose on 1 thread; "
          f"mean {result['fk_mean_iterations']:.3f} iterations (max {result['fk_max_iterations']}), "
          f"converged {result['fk_converged_fraction']:.6f} ({result['fk_not_converged']} not converged), "
          f"max |pose error| {pose_err:.2e}")
    print(f"FK pose by pose, {m} calls of Hexapod.fk: {result['fk_loop_public_api_us_per_pose']:.2f} µs/pose; "
          f"{m} calls of kernels.fk_newton with N = 1 (serial path, no FKResult): {result['fk_loop_kernel_direct_us_per_pose']:.2f} µs/pose")
    if t_c is not None:
        print(f"C reference Newton (same algorithm, one pose per call from a C loop, 1 thread; {c_info}): "
              f"{result['c_reference_us_per_pose']:.4f} µs/pose, mean {c_mean_it:.3f} iterations, "
              f"converged {c_conv_frac:.6f}; pkmcal batch FK is {us(t_c, args.n) / us(t_fk, args.n):.1f}x faster "
              f"({us(t_c, args.n) / us(t_fk_1thread, args.n):.1f}x on 1 thread)")
    else:
        print(f"C reference not run: {c_info}")
    print(f"peak memory: RSS {result['peak_rss_mb']:.1f} MB (whole process); "
          f"tracemalloc peak during the timed runs {result['tracemalloc_peak_mb']:.2f} MB")
    print(json.dumps(result))
    return result


if __name__ == "__main__":
    main(sys.argv[1:])
