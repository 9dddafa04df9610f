"""How often the gated correction is kept (docs/compensation.md), on N simulated machines,
each with its own kinematic errors (up to 0.5 mm, pkmcal.perturb) and its own measurements:

* ``printer``: a Kossel Mini probed at 60 random points for the calibration and 40 for the
  gate (σ 0.005 mm), over a flat bed and over a bed with a 0.3 mm bump;
* ``hexapod``: the stewart-prototype measured by a laser tracker (σ 0.01 mm) at 150 random
  poses and 40 held-out, with stiff legs and sagging under 600 N (the sag of the tests).

Printed: how many kept a correction. Run from the repository root:

    PYTHONPATH=src python3 examples/compensation/gate_rates.py 60 printer    # about 30 s
    PYTHONPATH=src python3 examples/compensation/gate_rates.py 10 hexapod    # about 80 s
"""

import dataclasses
import sys
import warnings

import pkmcal
from pkmcal.compensation.fit import compensate
from pkmcal.compensation.simulated import BedBump, Sag, with_bed, with_sag

n = int(sys.argv[1]) if len(sys.argv) > 1 else 15
which = sys.argv[2] if len(sys.argv) > 2 else "printer"
if which == "printer":
    m = pkmcal.load_machine("kossel-mini")
    s = pkmcal.load_setup("z-probe-klipper", m)
    sizes, lift, options = (60, 40), [0.0, 0.0, 1.0], {}
    errors = {"flat bed": lambda x, real: with_bed(x, real, s.sensor, BedBump(0.0, (0.0, 0.0), 1.0)),
              "bed with a bump": lambda x, real: with_bed(x, real, s.sensor, BedBump(0.3, (30.0, -20.0), 25.0))}
else:
    m = pkmcal.load_machine("stewart-prototype")
    s = pkmcal.load_setup("laser-tracker", m)
    sizes, lift, options = (150, 40), [0.0] * 6, {"degrees": (0, 1, 2)}
    sag = Sag((0.0, 0.0, -600.0), (100.0, 0.0, 200.0), 2.0e3)
    errors = {"stiff legs": lambda x, real: x, "sagging": lambda x, real: with_sag(x, real, s.sensor, sag)}
kept = dict.fromkeys(errors, 0)
for k in range(n):
    real = pkmcal.perturb(m, 0.5, seed=100 + k)
    cal_poses = pkmcal.plan(m, s, sizes[0], seed=200 + k, n_candidates=2000, algorithm="random").poses + lift
    held_poses = pkmcal.plan(m, s, sizes[1], seed=300 + k, n_candidates=1000, algorithm="random").poses + lift
    for label, error in errors.items():
        sim = error(pkmcal.simulate(m, real, s, cal_poses, seed=400 + k, ignore_limits=("leg_collision",)
                                    if which == "hexapod" else ()), real)
        held = error(pkmcal.simulate(m, real, s, held_poses, seed=500 + k, ignore_limits=("leg_collision",)
                                     if which == "hexapod" else ()), real)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = pkmcal.identify(m, s, sim.measurements)
        rep = compensate(res.mechanism, dataclasses.replace(s, sensor=res.sensor), sim.measurements,
                         held.measurements, **options)
        kept[label] += rep.accepted
        print(f"{label} {k}: {'kept' if rep.accepted else 'rejected'} ({rep.candidates[rep.chosen].label})",
              flush=True)
print("kept: " + ", ".join(f"{label} {v} of {n}" for label, v in kept.items()))
