"""``pkmcal export``: a machine file calibrated by ``pkmcal identify`` → LinuxCNC genhexkins
HAL lines and a JSON record.

The HAL points are parsed back and put through genhexkins' strut-length formula,
re-implemented independently in ``tests/io/test_export_linuxcnc.py`` from LinuxCNC's C source; they must
reproduce the calibrated machine's leg lengths: at random poses, and at the measured poses,
where the strut length is L0_i + λ_i of the calibrated offsets and the measured readings."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from test_export_linuxcnc import HALF_NM, STRUT_ROUNDING, genhexkins_inverse, parse_hal

from pkmcal.cli.main import cli
from pkmcal.io import load_machine, read_table
from pkmcal.io.export_linuxcnc import rounded_machine
from pkmcal.io.tables import format_table

POSE_NAMES = ("x", "y", "z", "a", "b", "c")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    """Simulated dial-indicator campaign on the paper 2 prototype, identified by the CLI."""
    d = tmp_path_factory.mktemp("export")
    rng = np.random.default_rng(11)
    home = load_machine("stewart-prototype").home_pose
    p = rng.uniform(-1, 1, (40, 6)) * np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])
    p[:, :3] += home[:3]
    (d / "poses.csv").write_text(format_table({n: p[:, k] for k, n in enumerate(POSE_NAMES)}))
    ok(run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
           "--poses", d / "poses.csv", "--seed", "3", "-o", d / "meas.csv"))
    ok(run("identify", "stewart-prototype", d / "meas.csv", "--setup", "indicators-prototype", "-o", d / "cal.yaml"))
    return d


def test_linuxcnc_export_reproduces_calibrated_leg_lengths(calibrated):
    d = calibrated
    ok(run("export", d / "cal.yaml", "--format", "linuxcnc", "-o", d / "k.hal"))
    text = (d / "k.hal").read_text()
    assert text.startswith("# genhexkins configuration") and "Units: mm" in text and "Rz(C) Ry(B) Rx(A)" in text
    base, platform, joints = parse_hal(text)
    cal = load_machine(d / "cal.yaml")
    # the calibrated joints rounded to 1 nm (export_linuxcnc.LINUXCNC_DECIMALS), exactly
    np.testing.assert_array_equal(base, rounded_machine(cal).base)
    np.testing.assert_array_equal(platform, rounded_machine(cal).platform)
    np.testing.assert_allclose(base, cal.base, rtol=0, atol=HALF_NM)
    assert not np.array_equal(cal.base, load_machine("stewart-prototype").base)  # it is the calibrated one
    # random poses: genhexkins' struts = the calibrated model's leg lengths
    rng = np.random.default_rng(2)
    poses = cal.home_pose + rng.uniform(-1, 1, (50, 6)) * np.array([20, 20, 10, *np.deg2rad([10, 10, 30])])
    deg = np.column_stack([poses[:, :3], np.rad2deg(poses[:, 3:])])
    ghk = np.array([genhexkins_inverse(base, platform, q) for q in deg])
    np.testing.assert_allclose(ghk, cal.leg_lengths(poses), rtol=0, atol=STRUT_ROUNDING + 1e-9)
    # measured poses: the calibrated FK of the readings, through genhexkins, gives L0 + λ
    lam = read_table(d / "meas.csv", [f"lambda{i}" for i in range(1, 7)]).values
    fk = cal.fk(lam)
    assert np.all(fk.converged)
    fk_deg = np.column_stack([fk.poses[:, :3], np.rad2deg(fk.poses[:, 3:])])
    ghk = np.array([genhexkins_inverse(base, platform, q) for q in fk_deg])
    L0 = np.array([joints[n][0] for n in range(6)])
    np.testing.assert_array_equal(L0, rounded_machine(cal).offset)
    np.testing.assert_allclose(ghk, L0 + lam, rtol=0, atol=1e-8 + STRUT_ROUNDING + HALF_NM)


def test_json_export_parameters_std_correlation(calibrated):
    d = calibrated
    ok(run("export", d / "cal.yaml", "--format", "json", "-o", d / "c.json"))
    j = json.loads((d / "c.json").read_text())
    cal = load_machine(d / "cal.yaml")
    assert j["units"]["length"] == "mm" and j["units"]["angle"] == "deg"
    assert "Rz(c) Ry(b) Rx(a)" in j["conventions"]["pose"]
    names = [p["name"] for p in j["parameters"]]
    assert names == list(cal.param_names)
    np.testing.assert_array_equal([p["value"] for p in j["parameters"]], cal.params)  # exact
    cov = cal.covariance
    std = {p["name"]: p["std"] for p in j["parameters"]}
    rec = j["calibration"]
    assert rec["method"] == "fk-residual" and rec["n_free"] == 39 and len(rec["gauge"]) == 3
    from pkmcal.identification.residuals import default_fixed_parameters

    held = set(default_fixed_parameters(cal))
    assert held == {f"gain_{i}" for i in range(1, 7)}
    for k, n in enumerate(names):
        if n in rec["gauge"] or n in held:
            assert std[n] is None  # held fixed: no uncertainty
        else:
            assert std[n] == pytest.approx(np.sqrt(cov[k, k]), rel=1e-15)
    corr = np.array(j["correlation"]["matrix"])
    idx = [names.index(n) for n in j["correlation"]["parameters"]]
    assert len(idx) == 39 == j["n_identified"]
    sub = cov[np.ix_(idx, idx)]
    s = np.sqrt(np.diag(sub))
    np.testing.assert_allclose(corr, sub / np.outer(s, s), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(corr, corr.T)
    assert np.all(np.diag(corr) == 1.0) and np.all(np.abs(corr) <= 1.0)
    assert j["home_pose"]["z"] == pytest.approx(cal.home_pose[2])


def test_export_is_deterministic_and_to_stdout(calibrated, tmp_path):
    d = calibrated
    for fmt in ("linuxcnc", "json"):
        ok(run("export", d / "cal.yaml", "--format", fmt, "-o", tmp_path / f"a.{fmt}"))
        ok(run("export", d / "cal.yaml", "--format", fmt, "-o", tmp_path / f"b.{fmt}"))
        a = (tmp_path / f"a.{fmt}").read_bytes()
        assert a == (tmp_path / f"b.{fmt}").read_bytes()
        assert ok(run("export", d / "cal.yaml", "--format", fmt)).stdout.encode() == a


def test_export_errors(calibrated, tmp_path):
    d = calibrated
    before = (d / "cal.yaml").read_bytes()
    res = run("export", d / "cal.yaml", "--format", "json", "-o", d / "cal.yaml")
    assert res.exit_code == 2 and "never overwrites its inputs" in res.stderr
    assert (d / "cal.yaml").read_bytes() == before
    res = run("export", "planar-2dof-3act", "--format", "linuxcnc", "-o", tmp_path / "p.hal")
    assert res.exit_code == 2 and "genhexkins" in res.stderr and "\n" not in res.stderr.strip()
    assert not (tmp_path / "p.hal").exists()
    # a planar machine exports as JSON (its parameters, angles in degrees)
    j = json.loads(ok(run("export", "planar-2dof-3act", "--format", "json")).stdout)
    assert j["parameters"] and all(p["unit"] in ("mm", "deg") for p in j["parameters"])
    # the machine's kind as `pkmcal machines` lists it, beside the model's class name of old
    assert j["machine"]["mechanism_kind"] == "planar-2dof-3act" and j["machine"]["kind"] == "Planar2Dof3Act"
    (tmp_path / "bad.yaml").write_text("name: x\nlegs: []\n")
    res = run("export", tmp_path / "bad.yaml", "--format", "json")
    assert res.exit_code == 2 and "bad.yaml" in res.stderr and "Traceback" not in res.output
