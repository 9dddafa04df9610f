"""A calibration re-expressed in another gauge (pkmcal.history.gauge) against an independent
reference: the same measurements refitted by the engine with that gauge held. The
re-expression is first order in the gauge shift t (the null space is taken at B's
parameters), so it differs from the refit by O(|t|²/size): for this printer's 0.1 mm errors
about 1e-4 mm, below 1 % of the smallest σ (0.005 mm); the bounds, 5 % of σ for the values
and 2 % for the σ themselves, leave a factor of 5 or more."""

from __future__ import annotations

import numpy as np
import pytest

import pkmcal
from pkmcal.workflow.record import with_calibration_record
from pkmcal.history.gauge import regauge
from pkmcal.history.stats import compare
from pkmcal.history.store import add_calibrated_file

GAUGE_A = ["angle_a", "radius_a", "radius_b"]
GAUGE_B = ["angle_a", "radius_a", "angle_b"]


@pytest.fixture(scope="module")
def two_gauges(tmp_path_factory):
    folder = tmp_path_factory.mktemp("gauge")
    machine = pkmcal.load_machine("kossel-mini")
    setup = pkmcal.load_setup("z-probe-klipper", machine)
    poses = pkmcal.plan(machine, setup, 30, seed=1, n_candidates=300).poses
    real = pkmcal.perturb(machine, 0.1, seed=11)
    sim = pkmcal.simulate(machine, real, setup, poses, seed=5, ignore_limits=("min_z",))
    recs = []
    for k, fix in enumerate((GAUGE_A, GAUGE_B)):
        result = pkmcal.identify(machine, setup, sim.measurements, fix=fix)
        path = folder / f"c{k}.yaml"
        pkmcal.save_machine(with_calibration_record(result, "kossel-mini", "m.csv", "z-probe-klipper", f"c{k}"), path)
        recs.append(add_calibrated_file(path, serial="S", db=folder / "h.sqlite"))
    return recs


def test_the_null_space_is_recorded_with_the_calibration(two_gauges):
    a, b = two_gauges
    for rec in (a, b):
        ns = rec.null_space
        assert len(ns["directions"]) == 3
        assert set(GAUGE_A) | set(GAUGE_B) <= set(ns["names"])


def test_a_calibration_re_expressed_in_another_gauge_equals_the_refit_in_it(two_gauges):
    a, b = two_gauges
    moved, how = regauge(b, a)
    assert moved is not None, how
    assert np.array_equal(moved.held, a.held)
    est = ~a.held
    assert np.all(np.abs(moved.values - a.values)[est] < 0.05 * a.std[est])
    assert np.allclose(moved.std[est], a.std[est], rtol=0.02)
    res = compare(a, b)
    assert res.comparable and res.regauged and not res.differ


def test_without_recorded_directions_different_gauges_are_not_compared(two_gauges):
    import dataclasses

    a, b = (dataclasses.replace(r, null_space=None) for r in two_gauges)
    res = compare(a, b)
    assert not res.comparable and "different gauges" in res.reason and "--fix" in res.reason


def test_a_fleet_takes_a_unit_in_another_gauge_in_the_reference_gauge(two_gauges):
    import dataclasses

    from pkmcal.history.stats import fleet

    a, b = two_gauges
    units = [a, dataclasses.replace(b, serial="S2"), dataclasses.replace(a, serial="S3")]
    rep = fleet(units, 1e-3)
    assert rep.regauged == ("S2",) and not rep.excluded and len(rep.units) == 3


def test_a_tight_hexapod_gets_its_null_space_from_poses_of_its_nominal_machine(tmp_path):
    """The calibrated stewart-prototype's home pose sits at a limit (no plan on it): the poses
    come from the nominal machine its record names; the indicators leave 3 directions."""
    from pkmcal.workflow.record import identified_setup_of

    machine = pkmcal.load_machine("stewart-prototype")
    setup = pkmcal.load_setup("indicators-prototype", machine)
    poses = pkmcal.plan(machine, setup, 40, seed=1, n_candidates=300).poses
    result = pkmcal.identify(machine, setup, pkmcal.simulate(machine, machine, setup, poses, seed=2).measurements)
    path = tmp_path / "hexapod.yaml"
    pkmcal.save_machine(with_calibration_record(result, "stewart-prototype", "m.csv", "indicators-prototype", "hx",
                                                setup=identified_setup_of(setup, result)), path)
    rec = add_calibrated_file(path, serial="HX", db=tmp_path / "h.sqlite")
    assert len(rec.null_space["directions"]) == len(result.gauge) == 3
    assert set(result.gauge) <= set(rec.null_space["names"])
