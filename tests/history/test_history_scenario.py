"""Issue 28's "must show": a history of 12 calibrations of 3 delta printers (kossel-mini,
Z probe, 30 probe points, the same plan on every printer, the gauge held explicitly as a farm's
calibration script would), each a real simulated campaign (pkmcal.simulate + pkmcal.identify,
written as calibrated machine files and recorded with ``add_calibrated_file``). Printer KM-1's
endstop_b slips by 0.25 mm before its third calibration.

Thresholds: every test at family-wise false-alarm probability ALPHA = 1e-6; the scenario makes
9 consecutive comparisons (a z family and a joint χ² each) and one fleet test, so a correct
implementation raises a false alarm with probability ≤ 19 × 1e-6 ≈ 2e-5 whatever the seeds.
The drift is 0.25 mm against a combined σ of about 0.009 mm (≈ 29 σ), the Bonferroni limit
5.2 σ: missed with probability < 1e-100. A fleet of 10 printers, one with a 3 mm endstop
error, checks the fleet test (α = 1e-3)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import pkmcal
from pkmcal.workflow.record import with_calibration_record
from pkmcal.cli.main import cli
from pkmcal.history.stats import compare, consecutive, fleet
from pkmcal.history.store import add_calibrated_file, open_history

ALPHA = 1e-6
DRIFT_MM = 0.25
GAUGE = ["angle_a", "radius_a", "radius_b"]
MONTH_S = 30 * 86400
EPOCH = 1798761600                      # 2027-01-01


@pytest.fixture(scope="module")
def campaign():
    machine = pkmcal.load_machine("kossel-mini")
    setup = pkmcal.load_setup("z-probe-klipper", machine)
    plan = pkmcal.plan(machine, setup, 30, seed=1, n_candidates=300)
    return machine, setup, plan.poses


def _calibrate(campaign, real, seed, folder, name, date_s, mp):
    machine, setup, poses = campaign
    # the probe points lie on the bed (z = 0): a printer whose errors put the bed below its nominal
    # lowest z still touches it there
    sim = pkmcal.simulate(machine, real, setup, poses, seed=seed, ignore_limits=("min_z",))
    assert not sim.dropped
    result = pkmcal.identify(machine, setup, sim.measurements, fix=GAUGE)
    mp.setenv("SOURCE_DATE_EPOCH", str(date_s))
    path = folder / f"{name}.yaml"
    pkmcal.save_machine(with_calibration_record(result, "kossel-mini", f"{name}.csv", "z-probe-klipper", name), path)
    return path


def _drifted(real, name, delta):
    p = real.params.copy()
    p[list(real.param_names).index(name)] += delta
    return real.with_params(p)


@pytest.fixture(scope="module")
def history(campaign, tmp_path_factory):
    folder = tmp_path_factory.mktemp("farm")
    db = folder / "farm.sqlite"
    machine = campaign[0]
    with pytest.MonkeyPatch.context() as mp:
        for u in range(3):
            real = pkmcal.perturb(machine, 0.1, seed=10 + u)
            for k in range(4):
                r = _drifted(real, "endstop_b", DRIFT_MM) if (u == 1 and k >= 2) else real
                path = _calibrate(campaign, r, 100 * u + k, folder, f"km{u}-{k}", EPOCH + k * MONTH_S + u * 3600, mp)
                add_calibrated_file(path, serial=f"KM-{u}", db=db)
    return db


def test_the_drift_is_flagged_with_its_sigma_and_nothing_else(history):
    with open_history(history, create=False) as hist:
        assert len(hist.records()) == 12
        found = []
        for serial in ("KM-0", "KM-1", "KM-2"):
            recs = hist.records(serial=serial)
            assert len(recs) == 4
            for k, c in enumerate(consecutive(recs, ALPHA)):
                assert c.comparable, c.reason
                assert len(c.rows) == 6 and "arm_a" in c.held and "radius_b" in c.held   # held never tested
                found += [(serial, k, r.name) for r in c.flagged]
                if c.jointly_flagged:
                    found.append((serial, k, "joint"))
                if (serial, k) == ("KM-1", 1):
                    drift = c
    assert found == [("KM-1", 1, "endstop_b"), ("KM-1", 1, "joint")]
    row = drift.flagged[0]
    assert abs(row.delta - DRIFT_MM) < 5 * row.sigma          # the slip, within its own uncertainty
    assert 0.003 < row.sigma < 0.03 and row.z == pytest.approx(row.delta / row.sigma)


def test_the_fleet_of_three_flags_nothing(history):
    with open_history(history, create=False) as hist:
        rep = fleet(hist.latest_per_serial(), ALPHA)
    assert len(rep.units) == 3 and not rep.excluded and not rep.flagged


def test_the_commands_show_the_drift(history, tmp_path):
    run = CliRunner()
    res = run.invoke(cli, ["history", "compare", "KM-1~2", "KM-1~1", "--alpha", str(ALPHA), "--db", str(history),
                           "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["flagged"] == ["endstop_b"] and d["differ"] and d["comparable"]
    res = run.invoke(cli, ["history", "compare", "KM-1~2", "KM-1~1", "--alpha", str(ALPHA), "--db", str(history)])
    assert res.exit_code == 0 and "changed beyond the combined uncertainty: endstop_b +0.2" in res.stdout, res.output
    res = run.invoke(cli, ["history", "compare", "KM-0~1", "KM-0", "--db", str(history)])
    assert res.exit_code == 0 and "no change beyond the combined uncertainty" in res.stdout, res.output
    res = run.invoke(cli, ["history", "list", "--db", str(history), "--json"])
    assert [r["serial"] for r in json.loads(res.stdout)].count("KM-1") == 4
    res = run.invoke(cli, ["history", "show", "KM-1", "--db", str(history)])
    assert res.exit_code == 0 and "endstop_b" in res.stdout and "held" in res.stdout
    res = run.invoke(cli, ["history", "fleet", "--db", str(history), "--json"])
    assert res.exit_code == 0 and json.loads(res.stdout)[0]["flagged"] == []
    for ext, magic in ((".png", b"\x89PNG"), (".svg", b"<?xml")):
        out = tmp_path / f"km1{ext}"
        res = run.invoke(cli, ["history", "plot", "KM-1", "-o", str(out), "--db", str(history)])
        assert res.exit_code == 0, res.output
        assert out.read_bytes().startswith(magic)
    res = run.invoke(cli, ["history", "plot", "KM-1", "-o", str(tmp_path / "x.pdf"), "--db", str(history)])
    assert res.exit_code == 2 and "png or .svg" in res.stderr


def test_a_fleet_flags_the_unit_outside_its_spread(campaign, tmp_path):
    """10 printers of one model; KM-7 assembled with endstop_c 3 mm off: flagged, nothing else
    (α = 1e-3 for the fleet)."""
    machine = campaign[0]
    recs = []
    with pytest.MonkeyPatch.context() as mp:
        for u in range(10):
            real = pkmcal.perturb(machine, 0.1, seed=50 + u)
            if u == 7:
                real = _drifted(real, "endstop_c", 3.0)
            path = _calibrate(campaign, real, 500 + u, tmp_path, f"f{u}", EPOCH + u * 3600, mp)
            recs.append(add_calibrated_file(path, serial=f"KM-{u}", db=tmp_path / "fleet.sqlite"))
    rep = fleet(recs, 1e-3)
    assert [(r.serial, r.name) for r in rep.flagged] == [("KM-7", "endstop_c")]
    assert rep.flagged[0].value - rep.flagged[0].fleet_mean == pytest.approx(3.0, abs=5 * rep.flagged[0].fleet_std)
    assert compare(recs[0], recs[1]).comparable


def test_calibrations_in_different_gauges_are_compared_in_one(campaign, tmp_path):
    """KM-1 again, its farm having changed its calibration script in March: January and
    February held the gauge angle_a, radius_a, radius_b (--fix), March and April the
    automatic one (angle_a, radius_a, angle_b with these seeds). Each calibration is
    re-expressed in the previous one's gauge along the unidentifiable directions recorded
    with it (pkmcal.history.gauge), and the slip, at the change of gauge, is still the only
    thing flagged."""
    machine, setup, poses = campaign
    real = pkmcal.perturb(machine, 0.1, seed=11)
    db = tmp_path / "auto.sqlite"
    with pytest.MonkeyPatch.context() as mp:
        for k in range(4):
            r = _drifted(real, "endstop_b", DRIFT_MM) if k >= 2 else real
            sim = pkmcal.simulate(machine, r, setup, poses, seed=100 + k, ignore_limits=("min_z",))
            result = pkmcal.identify(machine, setup, sim.measurements, fix=GAUGE if k < 2 else None)
            mp.setenv("SOURCE_DATE_EPOCH", str(EPOCH + k * MONTH_S))
            path = tmp_path / f"auto{k}.yaml"
            pkmcal.save_machine(with_calibration_record(result, "kossel-mini", "m.csv", "z-probe-klipper", f"a{k}"),
                                path)
            add_calibrated_file(path, serial="KM-1", db=db)
    with open_history(db, create=False) as hist:
        recs = hist.records()
    held = [tuple(n for n, h in zip(r.names, r.held) if h) for r in recs]
    assert held[0] == held[1] and held[2] == held[3] and held[1] != held[2]      # the case this test is about
    comparisons = consecutive(recs, ALPHA)
    assert all(c.comparable for c in comparisons), [c.reason for c in comparisons]
    assert [bool(c.regauged) for c in comparisons] == [False, True, False]
    flagged = [(k, r.name) for k, c in enumerate(comparisons) for r in c.flagged]
    assert flagged == [(1, "endstop_b")]
    assert [k for k, c in enumerate(comparisons) if c.jointly_flagged] == [1]
    row = comparisons[1].flagged[0]
    assert abs(row.delta - DRIFT_MM) < 5 * row.sigma
