"""How often the gated correction is kept (docs/compensation.md): N simulated Kossel Minis
(kinematic errors of up to 0.5 mm, each its own draw), each probed at 60 random points for the
calibration and 40 for the gate (σ 0.005 mm), over a flat bed and over a bed with a 0.3 mm
bump; printed: how many kept a mesh. Run from the repository root (N = 15 takes a few minutes):

    PYTHONPATH=src python3 examples/compensation/gate_rates.py 15
"""

import dataclasses
import sys
import warnings

import pkmcal
from pkmcal.compensation.fit import compensate
from pkmcal.compensation.simulated import BedBump, with_bed

n = int(sys.argv[1]) if len(sys.argv) > 1 else 15
m = pkmcal.load_machine("kossel-mini")
s = pkmcal.load_setup("z-probe-klipper", m)
lift = [0.0, 0.0, 1.0]
kept = {"flat": 0, "bump": 0}
for k in range(n):
    real = pkmcal.perturb(m, 0.5, seed=100 + k)
    cal_poses = pkmcal.plan(m, s, 60, seed=200 + k, n_candidates=1000, algorithm="random").poses + lift
    held_poses = pkmcal.plan(m, s, 40, seed=300 + k, n_candidates=1000, algorithm="random").poses + lift
    for label, bed in (("flat", BedBump(0.0, (0.0, 0.0), 1.0)), ("bump", BedBump(0.3, (30.0, -20.0), 25.0))):
        sim = with_bed(pkmcal.simulate(m, real, s, cal_poses, seed=400 + k), real, s.sensor, bed)
        held = with_bed(pkmcal.simulate(m, real, s, held_poses, seed=500 + k), real, s.sensor, bed)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = pkmcal.identify(m, s, sim.measurements)
        rep = compensate(res.mechanism, dataclasses.replace(s, sensor=res.sensor), sim.measurements,
                         held.measurements)
        kept[label] += rep.accepted
        print(f"{label} {k}: {'kept' if rep.accepted else 'rejected'} ({rep.candidates[rep.chosen].label})",
              flush=True)
print(f"kept: flat bed {kept['flat']} of {n}, bed with a bump {kept['bump']} of {n}")
