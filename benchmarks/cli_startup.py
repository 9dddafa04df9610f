"""How fast ``pkmcal`` starts: wall time of short commands, and which imports cost it.

Workload (each a fresh process, as a user types it; caches warm: one untimed run first):

* ``pkmcal --help``                                     target ≤ 0.3 s
* ``pkmcal machines``                                   target ≤ 0.3 s
* ``pkmcal ik stewart-prototype --poses POSES.csv`` on 10 poses target ≤ 1 s

Each command is run ``--repeats`` times through the installed entry point's interpreter
(``sys.executable -m pkmcal.cli.main``, no shell or pyenv shim in the way); reported are the
best and the median wall time, and the bare interpreter's start (``python -c pass``) for
scale. Then each command once more under ``python -X importtime``: the cumulative import
time of the heavy libraries (NumPy, SciPy, numba, pydantic, matplotlib) it loaded, and its
slowest top-level imports, so a regression names its cause.

The last line of output is one JSON object (``help_s``, ``machines_s``, ``ik_10_s``: best
wall times in seconds; ``*_median_s``; ``python_s``; ``imports``).

Usage: ``python benchmarks/cli_startup.py [--repeats 9] [--quick]`` (``--quick``: one repeat)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time

from _quick import parse_args  # benchmarks/_quick.py

HEAVY = ("numpy", "scipy", "numba", "pydantic", "matplotlib")
TARGETS = {"help": 0.3, "machines": 0.3, "ik_10": 1.0}

#: Ten reachable poses of stewart-prototype (mm, deg): home z = 365.22 mm, small moves.
POSES_10 = """x,y,z,a,b,c
0,0,365.2,0,0,0
5,0,365.2,0,0,0
-5,3,362,1,0,0
2,-4,368,0,1,0
0,0,360,0,0,2
3,3,366,-1,1,0
-3,-3,364,1,-1,1
4,-2,363,0.5,0.5,-0.5
-2,4,367,-0.5,0,0.5
1,1,365,0,-1,-1
"""


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def _time(cmd: list[str], repeats: int) -> tuple[float, float]:
    subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)   # warm caches
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=True)
        times.append(time.perf_counter() - t0)
    return min(times), statistics.median(times)


def _imports(cmd: list[str]) -> dict:
    """Cumulative import time (s) of the heavy libraries and the five slowest top-level imports."""
    err = subprocess.run([cmd[0], "-X", "importtime", *cmd[1:]], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, check=True).stderr
    heavy: dict[str, float] = {}
    top: list[tuple[float, str]] = []
    for line in err.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, cum, name = line.split("|", 2)
        try:
            us = int(cum.strip())
        except ValueError:          # the header line
            continue
        depth = len(name) - len(name.lstrip(" "))
        name = name.strip()
        if name in HEAVY:
            heavy[name] = max(heavy.get(name, 0.0), us / 1e6)
        if depth == 1:
            top.append((us / 1e6, name))
    top.sort(reverse=True)
    return {"heavy_s": heavy, "slowest_top_level_s": {n: round(t, 4) for t, n in top[:5]}}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=9)
    args = parse_args(ap, argv, repeats=1)
    py = sys.executable
    with tempfile.TemporaryDirectory() as tmp:
        poses = os.path.join(tmp, "poses10.csv")
        with open(poses, "w") as f:
            f.write(POSES_10)
        cmds = {
            "help": [py, "-m", "pkmcal.cli.main", "--help"],
            "machines": [py, "-m", "pkmcal.cli.main", "machines"],
            "ik_10": [py, "-m", "pkmcal.cli.main", "ik", "stewart-prototype", "--poses", poses],
        }
        print(f"machine: {cpu_model()}, {os.cpu_count()} cores, load average "
              f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}; Python {platform.python_version()}")
        python_s = _time([py, "-c", "pass"], args.repeats)[0]
        print(f"bare interpreter start (python -c pass): {python_s:.3f} s")
        out: dict = {"python_s": round(python_s, 4), "imports": {}, "quick": args.quick}
        for key, cmd in cmds.items():
            best, med = _time(cmd, args.repeats)
            out[f"{key}_s"], out[f"{key}_median_s"] = round(best, 4), round(med, 4)
            out["imports"][key] = _imports(cmd)
            verdict = "met" if best <= TARGETS[key] else "MISSED"
            heavy = ", ".join(f"{k} {v:.3f}" for k, v in out["imports"][key]["heavy_s"].items()) or "none"
            print(f"{key:<9} best {best:.3f} s, median {med:.3f} s (target ≤ {TARGETS[key]} s: {verdict}); "
                  f"heavy imports (cumulative s): {heavy}")
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
