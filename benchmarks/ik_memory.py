"""Peak memory and time of ``pkmcal ik`` on a large pose file (issue 10 item 7: a million poses
peaked at 5.1 GB when every pose was computed and formatted at once).

Workload: ``--poses`` random reachable poses of ``stewart-prototype`` (uniform in home ±
(8, 8, 4 mm, 2, 2, 4 deg), seed 0) written as a pose CSV, then ``pkmcal ik stewart-prototype
--poses POSES.csv -o LEGS.csv`` in a fresh process (``sys.executable -m pkmcal.cli.main``). Measured:
the child's peak resident set size (``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss``, the
figure ``/usr/bin/time -v`` prints as "Maximum resident set size"; the one-pose warm-up run
that loads the compiled kernels' cache first is far smaller), its wall time, the peak
per pose, and the SHA-256 of the output (the bytes do not depend on how the work is split).

The last line of output is one JSON object (``poses``, ``peak_rss_mb``, ``wall_s``,
``bytes_per_pose``, ``output_sha256``, ``quick``).

Usage: ``python benchmarks/ik_memory.py [--poses 1000000] [--quick]`` (``--quick``: 20,500
poses, three of the blocks ``pkmcal ik`` computes and writes at a time, the last one partial)
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from _quick import parse_args  # benchmarks/_quick.py
from pkmcal.cli.kinematics_cmds import _IK_BLOCK
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=1_000_000)
    args = parse_args(ap, None, poses=2 * _IK_BLOCK + 500)
    rng = np.random.default_rng(0)
    p = rng.uniform(-1, 1, (args.poses, 6)) * np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])
    p[:, :3] += stewart_prototype().home_pose[:3]
    with tempfile.TemporaryDirectory() as d:
        poses, legs = os.path.join(d, "poses.csv"), os.path.join(d, "legs.csv")
        with open(poses, "w") as fh:
            fh.write(format_table({k: p[:, i] for i, k in enumerate("xyzabc")}))
        del p
        with open(os.path.join(d, "warm.csv"), "w") as fh:  # compile/load the numba kernels' cache first
            fh.write("x,y,z,a,b,c\n0,0,365,0,0,0\n")
        subprocess.run([sys.executable, "-m", "pkmcal.cli.main", "ik", "stewart-prototype", "--poses", fh.name],
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "pkmcal.cli.main", "ik", "stewart-prototype", "--poses", poses, "-o", legs],
                       check=True, stderr=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        peak_kb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss  # KiB on Linux
        with open(legs, "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} CPUs, "
          f"Python {platform.python_version()}")
    print(f"pkmcal ik on {args.poses} poses: peak RSS {peak_kb / 1024:.0f} MB "
          f"({peak_kb * 1024 / args.poses:.0f} bytes per pose), {wall:.1f} s wall")
    print(json.dumps({"poses": args.poses, "peak_rss_mb": round(peak_kb / 1024, 1), "wall_s": round(wall, 2),
                      "bytes_per_pose": round(peak_kb * 1024 / args.poses, 1), "output_sha256": digest,
                      "quick": args.quick}))


if __name__ == "__main__":
    main()
