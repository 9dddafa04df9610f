"""Writes campaign.csv and heldout.csv: a simulated motion-capture calibration of hexapod.yaml
(docs/tutorial-real-hexapod.md), with every complication of a real one. Run from this folder:

    python make_campaign.py           # writes the two files (same bytes every time)
    python make_campaign.py --truth   # and prints the real machine's gains

The "real" machine: the drawing's joints off by up to 1 mm, leg offsets likewise, and every
ball screw's lead 1 % off (gains 4.95..5.05 mm/rev). The mocap system is set up twice (two
sessions, its frame moved between them); the marker body stays on the platform. The files are
written as a mocap export merged with the encoder log: positions in metres, orientations as
unit quaternions qx,qy,qz,qw, the legs in motor revolutions. One reading is stuck at the end of
its stroke and one pose has a 5 mm mocap glitch.
"""

from __future__ import annotations

import csv
import dataclasses
import os
import sys

import numpy as np
from scipy.spatial.transform import Rotation

import pkmcal
from pkmcal.identification.simulation import simulate_campaign, simulate_sessions
from pkmcal.sensors.full_pose import FullPoseSensor

SEED = 2026
GAIN_ERRORS = np.array([0.010, -0.008, 0.006, -0.010, 0.004, -0.006])   # relative lead errors
WORLDS = np.array([[1512.3, -787.9, 296.2, 0.4, -0.3, 121.7],           # mm, deg: session 1,
                   [1488.0, -812.5, 301.4, -0.2, 0.5, 118.9]])          # and after it was set up again
TOOL = np.array([3.8, -2.1, 36.4, 1.2, -0.8, 44.1])                     # the marker body on the platform
#: Where the files are read and written (this folder; the tests point it elsewhere).
HERE = os.path.dirname(os.path.abspath(__file__))
CLIPPED = (17, 2, 10.0)       # data row (from 1), leg index, reading stuck at the stroke's end (rev)
GLITCH = (41, 5.0)            # data row, mocap x error (mm)


def _sensor(world_deg, tool_deg):
    to_internal = lambda v: np.r_[v[:3], np.deg2rad(v[3:])]  # noqa: E731
    return FullPoseSensor(world=to_internal(world_deg), tool=to_internal(tool_deg))


def _rows(readings, sensor_readings, sessions):
    """The export's rows: session, lambda1..6 (rev), x, y, z (m), qx, qy, qz, qw."""
    out = []
    for label, q, y in zip(sessions, readings, sensor_readings):
        quat = Rotation.from_euler("ZYX", y[[5, 4, 3]]).as_quat()          # x, y, z, w (scipy)
        out.append([label, *(f"{v:.6f}" for v in q), *(f"{v / 1000:.7f}" for v in y[:3]),
                    *(f"{v:.9f}" for v in quat)])
    return out


def _write(path, rows):
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["session", "lambda1", "lambda2", "lambda3", "lambda4", "lambda5", "lambda6",
                    "x", "y", "z", "qx", "qy", "qz", "qw"])
        w.writerows(rows)


def main() -> None:
    nominal = pkmcal.load_machine(os.path.join(HERE, "hexapod.yaml"))
    setup = pkmcal.load_setup(os.path.join(HERE, "mocap.yaml"), nominal)
    rng = np.random.default_rng(SEED)
    real = pkmcal.perturb(nominal, 1.0, seed=SEED)
    rho = real.params
    for i, e in enumerate(GAIN_ERRORS):
        rho[real.param_names.index(f"gain_{i + 1}")] *= 1.0 + e
    real = real.with_params(rho, name="lab-hexapod-as-built")
    sensors = tuple(_sensor(w, TOOL) for w in WORLDS)
    plan = pkmcal.plan(nominal, setup, 60, seed=SEED, n_candidates=1500)
    sim = simulate_sessions(nominal, real, setup, plan.poses, sensors, rng, ignore_limits=("leg_collision",))
    rows = _rows(sim.actuator_readings, sim.sensor_readings, [sim.sessions.labels[k] for k in sim.sessions.index])
    row, leg, stuck = CLIPPED
    rows[row - 1][1 + leg] = f"{stuck:.6f}"
    row, dx = GLITCH
    rows[row - 1][7] = f"{float(rows[row - 1][7]) + dx / 1000:.7f}"
    _write(os.path.join(HERE, "campaign.csv"), rows)
    held = pkmcal.plan(nominal, setup, 20, algorithm="random", seed=SEED + 1, n_candidates=1500).poses
    sim2 = simulate_campaign(nominal, real, dataclasses.replace(setup, sensor=sensors[1]), held, rng,
                             ignore_limits=("leg_collision",))
    _write(os.path.join(HERE, "heldout.csv"), _rows(sim2.actuator_readings, sim2.sensor_readings, ["2"] * len(sim2.kept)))
    if "--truth" in sys.argv:
        print("real gains (mm/rev):", ", ".join(f"{g:.4f}" for g in real.reading_gains()))


if __name__ == "__main__":
    main()
