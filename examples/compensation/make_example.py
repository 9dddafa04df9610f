"""Writes the compensation example files (docs/compensation.md, the --help examples of
pkmcal compensate and correct): a simulated Kossel Mini probed over a bed with a 0.3 mm bump
(its calibration probing and 40 held-out points), a short print program, targets, and a
LinuxCNC program for the stewart-prototype hexapod. Run from the repository root:

    PYTHONPATH=src python3 examples/compensation/make_example.py
"""

from pathlib import Path

import numpy as np

import pkmcal
from pkmcal.compensation.simulated import BedBump, with_bed

HERE = Path(__file__).resolve().parent
BUMP = BedBump(0.3, (30.0, -20.0), 25.0)

m = pkmcal.load_machine("kossel-mini")
s = pkmcal.load_setup("z-probe-klipper", m)
real = pkmcal.perturb(m, 0.5, seed=2)
lift = [0.0, 0.0, 1.0]      # probed 1 mm above the bed plane: no real pose below min_z
for name, n, seed in (("warped-bed-meas.csv", 60, 1), ("warped-bed-heldout.csv", 40, 5)):
    poses = pkmcal.plan(m, s, n, seed=seed, n_candidates=1000, algorithm="random").poses + lift
    sim = with_bed(pkmcal.simulate(m, real, s, poses, seed=seed + 2), real, s.sensor, BUMP)
    pkmcal.save_measurements(sim.measurements, m, s, HERE / name)

lines = ["; a first layer over the bump (pkmcal example)", "G28", "G90", "M83", "G1 X-40 Y-40 Z5 F6000"]
for k, y in enumerate(np.arange(-40.0, 41.0, 10.0)):
    x0, x1 = (-40.0, 60.0) if k % 2 == 0 else (60.0, -40.0)
    lines += [f"G0 X{x0:g} Y{y:g} Z0.3", f"G1 X{x1:g} Y{y:g} E4.2 F1800"]
lines += ["G0 Z10", "M84"]
(HERE / "part.gcode").write_text("\n".join(lines) + "\n")
(HERE / "targets.csv").write_text("x,y,z\n0,0,0.3\n30,-20,0.3\n-50,40,0.3\n")

hexa = pkmcal.load_machine("stewart-prototype")
home = hexa.home_pose
ngc = ["(hexapod program, pkmcal example: mm and degrees)", "G21 G90"]
for dx, dy, dz, a in ((0, 0, 0, 0), (5, 0, 2, 1), (5, 5, 4, 0), (0, 5, 2, -1), (0, 0, 0, 0)):
    p = home + [dx, dy, dz, np.deg2rad(a), 0.0, 0.0]
    ngc.append("G1 X%.3f Y%.3f Z%.3f A%.3f B%.3f C%.3f F200" % (*p[:3], *np.rad2deg(p[3:])))
ngc.append("M2")
(HERE / "hexapod.ngc").write_text("\n".join(ngc) + "\n")
