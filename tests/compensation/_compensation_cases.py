"""Simulated campaigns of the compensation tests (cached per test session): a delta printer
over a warped bed and over a flat one, a hexapod that sags under its load and one that does
not. Each: the nominal and true machines, the setup, the calibration and held-out
measurements, the identified machine and its setup, and the unmodelled error."""

from __future__ import annotations

import dataclasses
import functools
import warnings
from dataclasses import dataclass

import pkmcal
from pkmcal.compensation.simulated import BedBump, Sag, with_bed, with_sag

#: The warped bed: a 0.3 mm bump of 25 mm width off centre, ~ 60 times the probe's noise.
BUMP = BedBump(0.3, (30.0, -20.0), 25.0)
#: The sag: 600 N whose centre of mass sits 100 mm beside and 200 mm above the platform, on
#: legs of 2 N/um (a light positioner): up to about 1 mm, of which the calibration absorbs
#: all but a few hundredths (docs/compensation.md).
SAG = Sag((0.0, 0.0, -600.0), (100.0, 0.0, 200.0), 2.0e3)


@dataclass(frozen=True)
class Case:
    nominal: object
    real: object
    setup: object
    calibration: object          # SimulationResult
    heldout: object              # SimulationResult
    calibrated: object           # the identified machine
    cal_setup: object            # the setup with the identified sensor
    error: object                # BedBump, Sag or None


def _identify(nominal, setup, sim):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # a fit over an unmodelled error is 'refused' by its chi2; we want it anyway
        res = pkmcal.identify(nominal, setup, sim.measurements)
    return res.mechanism, dataclasses.replace(setup, sensor=res.sensor)


@functools.lru_cache(maxsize=None)
def delta(warped: bool) -> Case:
    m = pkmcal.load_machine("kossel-mini")
    s = pkmcal.load_setup("z-probe-klipper", m)
    real = pkmcal.perturb(m, 0.5, seed=2)
    # probed 1 mm above the bed plane (the reading is the height), so that no real pose ends
    # below the printer's min_z and is dropped; random points cover the bed as a mesh needs
    lift = [0.0, 0.0, 1.0]
    cal_poses = pkmcal.plan(m, s, 60, seed=1, n_candidates=1000, algorithm="random").poses + lift
    held_poses = pkmcal.plan(m, s, 40, seed=5, n_candidates=1000, algorithm="random").poses + lift
    sim = pkmcal.simulate(m, real, s, cal_poses, seed=3)
    held = pkmcal.simulate(m, real, s, held_poses, seed=4)
    if warped:
        sim, held = (with_bed(x, real, s.sensor, BUMP) for x in (sim, held))
    cal, cal_setup = _identify(m, s, sim)
    return Case(m, real, s, sim, held, cal, cal_setup, BUMP if warped else None)


@functools.lru_cache(maxsize=None)
def hexapod(sagging: bool) -> Case:
    m = pkmcal.load_machine("stewart-prototype")
    s = pkmcal.load_setup("laser-tracker", m)
    real = pkmcal.load_machine("stewart-prototype-real")
    cal_poses = pkmcal.plan(m, s, 150, seed=1, n_candidates=2000, algorithm="random").poses
    held_poses = pkmcal.plan(m, s, 40, seed=5, n_candidates=1000, algorithm="random").poses
    sim = pkmcal.simulate(m, real, s, cal_poses, seed=3)
    held = pkmcal.simulate(m, real, s, held_poses, seed=4)
    if sagging:
        sim, held = (with_sag(x, real, s.sensor, SAG) for x in (sim, held))
    cal, cal_setup = _identify(m, s, sim)
    return Case(m, real, s, sim, held, cal, cal_setup, SAG if sagging else None)
