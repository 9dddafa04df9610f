"""Geometric calibration first, then the mesh, and what each gains (docs/compensation.md):
a simulated Kossel Mini (kinematic errors of up to 0.5 mm and 0.03 deg, pkmcal.perturb seed
2), probed with a Z probe at 60 random points (σ 0.005 mm) for the fits and at 40 others
for the held-out gate, over a flat bed and over a bed with a 0.3 mm bump. A first layer
(z = 0.3 mm) is commanded on a 10 mm grid within 70 mm of the centre through the firmware's
nominal kinematics, five ways; printed: the nozzle's height above the real bed minus 0.3 mm
(RMS, max |e|) and its horizontal error (RMS, max), mm. Run from the repository root:

    PYTHONPATH=src python3 examples/compensation/order_of_steps.py
"""

import dataclasses
import warnings

import numpy as np

import pkmcal
from pkmcal.compensation.apply import commands_for
from pkmcal.compensation.fit import compensate
from pkmcal.compensation.simulated import BedBump, with_bed

m = pkmcal.load_machine("kossel-mini")
s = pkmcal.load_setup("z-probe-klipper", m)
real = pkmcal.perturb(m, 0.5, seed=2)
lift = [0.0, 0.0, 1.0]
cal_poses = pkmcal.plan(m, s, 60, seed=1, n_candidates=1000, algorithm="random").poses + lift
held_poses = pkmcal.plan(m, s, 40, seed=5, n_candidates=1000, algorithm="random").poses + lift
g = np.stack(np.meshgrid(np.arange(-70, 71, 10.0), np.arange(-70, 71, 10.0)), axis=-1).reshape(-1, 2)
g = g[np.hypot(g[:, 0], g[:, 1]) <= 70]
targets = np.column_stack([g, np.full(len(g), 0.3)])

for label, bed in (("flat bed", BedBump(0.0, (0.0, 0.0), 1.0)), ("bed with a 0.3 mm bump", BedBump(0.3, (30.0, -20.0), 25.0))):
    sim = with_bed(pkmcal.simulate(m, real, s, cal_poses, seed=3), real, s.sensor, bed)
    held = with_bed(pkmcal.simulate(m, real, s, held_poses, seed=4), real, s.sensor, bed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = pkmcal.identify(m, s, sim.measurements)
        robust = pkmcal.identify(m, s, sim.measurements, loss="cauchy")        # identify --loss cauchy
    cal, cal_setup = res.mechanism, dataclasses.replace(s, sensor=res.sensor)
    rob, rob_setup = robust.mechanism, dataclasses.replace(s, sensor=robust.sensor)
    mesh_alone = compensate(m, s, sim.measurements, held.measurements)          # the nominal model's residuals
    mesh_after = compensate(cal, cal_setup, sim.measurements, held.measurements)
    mesh_robust = compensate(rob, rob_setup, sim.measurements, held.measurements)

    def printed(commands):
        fk = real.fk(m.ik(commands), guess=targets)
        p = fk.poses
        dz = p[:, 2] - bed(p[:, :2]) - targets[:, 2]
        dxy = np.hypot(*(p[:, :2] - targets[:, :2]).T)
        return (np.sqrt(np.mean(dz**2)), np.max(np.abs(dz)), np.sqrt(np.mean(dxy**2)), np.max(dxy))

    # the models' min_z (z = 0 of each model) is not the real bed: not checked here
    free = ("min_z",)
    rows = [("nominal config, no mesh", targets),
            ("mesh alone" + ("" if mesh_alone.accepted else " (rejected: none)"),
             commands_for(m, m, mesh_alone.field, targets, free).commands),
            ("geometric calibration alone", commands_for(cal, m, None, targets, free).commands),
            ("calibration, then the mesh" + ("" if mesh_after.accepted else " (rejected: none)"),
             commands_for(cal, m, mesh_after.field, targets, free).commands),
            ("calibration --loss cauchy, then the mesh" + ("" if mesh_robust.accepted else " (rejected: none)"),
             commands_for(rob, m, mesh_robust.field, targets, free).commands)]
    print(f"{label}: height error RMS / max, horizontal error RMS / max (mm), {len(targets)} points")
    for name, cmd in rows:
        print(f"  {name:<48} {' / '.join(f'{v:.3f}' for v in printed(cmd)[:2]):>14}   "
              f"{' / '.join(f'{v:.3f}' for v in printed(cmd)[2:]):>14}")
    for what, rep in (("mesh alone", mesh_alone), ("mesh after calibration", mesh_after)):
        print(f"  {what}: {rep.candidates[rep.chosen].label}; {rep.reason}")
