"""``plan --pattern iso9283``, ``verify`` with the ISO 9283 figures, ``identifiability
--accuracy``: the command-line edges of :mod:`pkmcal.identification.iso9283`, checked against
the machines' own kinematics and closed forms."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from helpers import assert_user_error
from pkmcal.api import load_machine
from pkmcal.cli.main import cli
from pkmcal.identification.iso9283 import detect_pattern
from pkmcal.io.tables import read_table

CYCLES = 5


def _run(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """A calibration of the prototype on 30 planned full-pose measurements, and the ISO 9283
    pattern in 5 cycles."""
    d = tmp_path_factory.mktemp("iso")
    _run("plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", 30, "--seed", 1, "-o", d / "poses.csv")
    _run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "full-pose-paper1",
         "--poses", d / "poses.csv", "--seed", 2, "--ignore-limit", "leg_collision", "-o", d / "meas.csv")
    _run("identify", "stewart-prototype", d / "meas.csv", "--setup", "full-pose-paper1", "-o", d / "cal.yaml")
    _run("plan", "stewart-prototype", "--setup", "full-pose-paper1", "--pattern", "iso9283", "--n-poses", CYCLES,
         "-o", d / "iso.csv")
    return d


def test_plan_writes_the_pattern(campaign):
    m = load_machine("stewart-prototype")
    names = ["x", "y", "z", "a", "b", "c", "iso_pose", "cycle"]
    t = read_table(campaign / "iso.csv", names, kinds={})
    assert len(t[names[0]]) == 5 * CYCLES
    poses = t[names[:6]]
    found = detect_pattern(m, poses)
    assert not isinstance(found, str)
    assert np.array_equal(found[0], t["iso_pose"].astype(int))
    assert np.array_equal(t["cycle"].astype(int), np.repeat(np.arange(1, CYCLES + 1), 5))


def test_plan_pattern_refuses_selection_options(campaign):
    res = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--pattern", "iso9283",
                                   "--grid", "3", "-o", str(campaign / "never.csv")])
    assert_user_error(res, "--grid", "--pattern iso9283")
    assert not (campaign / "never.csv").exists()


def test_verify_real_reports_the_exact_figures(campaign):
    """AP_P at each pose = ‖p_r − p_c‖ of the real machine's FK of the calibrated model's IK
    (every cycle the same pose: RP 0), and the predicted 95 % bound printed beside it."""
    res = _run("verify", campaign / "cal.yaml", "--real", "stewart-prototype-real", "--poses", campaign / "iso.csv",
               "--compare", "commanded", "--json")
    iso = json.loads(res.stdout)["iso9283"]
    cal, real = load_machine(str(campaign / "cal.yaml")), load_machine("stewart-prototype-real")
    m = load_machine("stewart-prototype")
    names = ["x", "y", "z", "a", "b", "c"]
    poses = read_table(campaign / "iso.csv", names, kinds={})[names][:5]
    poses[:, 3:] = np.deg2rad(poses[:, 3:])
    fk = real.fk(cal.ik(poses), guess=poses)
    want = np.linalg.norm(fk.poses[:, :3] - poses[:, :3], axis=1)
    got = {f["pose"]: f for f in iso["figures"] if f["figure"] == "AP_P"}
    for i in range(5):
        assert got[f"P{i + 1}"]["value_mm"] == pytest.approx(want[i], rel=1e-9, abs=1e-12)
        assert got[f"P{i + 1}"]["U_mm"] == 0.0
    rp = [f["value_mm"] for f in iso["figures"] if f["figure"] == "RP_l"]
    assert max(rp) < 1e-9                                             # round-off of identical poses
    assert set(iso["predicted_AP_P_95_mm"]) == {f"P{i}" for i in range(1, 6)}
    assert detect_pattern(m, poses) == "not five poses repeated in cycles"
    text = _run("verify", campaign / "cal.yaml", "--real", "stewart-prototype-real", "--poses", campaign / "iso.csv",
                "--compare", "commanded").stdout
    assert "ISO 9283 (P1..P5 of the test cube, 5 cycles): exact values" in text


def test_verify_measured_reports_figures_with_uncertainty(campaign):
    """Measured by paper 1's full-pose instrument (no frame to register: readings = pose),
    U of AP_x is 2 σ/√n exactly (σ = 0.025/√3 mm, uniform), of AP_a 2 σ_a/√n."""
    _run("simulate", campaign / "cal.yaml", "--real", "stewart-prototype-real", "--setup", "full-pose-paper1",
         "--poses", campaign / "iso.csv", "--seed", 5, "-o", campaign / "iso-meas.csv")
    res = _run("verify", campaign / "cal.yaml", "--held-out", campaign / "iso-meas.csv", "--setup",
               "full-pose-paper1", "--json")
    iso = json.loads(res.stdout)["iso9283"]
    by = {(f["figure"], f["pose"]): f for f in iso["figures"]}
    sigma, sigma_a = 0.025 / math.sqrt(3), 0.001 / math.sqrt(3)
    for i in range(1, 6):
        assert by[("AP_x", f"P{i}")]["U_mm"] == pytest.approx(2 * sigma / math.sqrt(CYCLES), rel=1e-8)
        assert by[("AP_a", f"P{i}")]["U_deg"] == pytest.approx(np.rad2deg(2 * sigma_a / math.sqrt(CYCLES)), rel=1e-6)
    assert "registration" not in iso["uncertainty"]


def test_indicators_on_the_pattern_say_why_not(campaign):
    """Held-out data in the pattern read by dial indicators: no ISO figures, and why."""
    from pkmcal.api import load_measurements, load_setup
    from pkmcal.identification.iso9283 import heldout_figures

    m = load_machine("stewart-prototype")
    _run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
         "--poses", campaign / "iso.csv", "--seed", 5, "-o", campaign / "iso-ind.csv")
    setup = load_setup("indicators-prototype", m)
    why = heldout_figures(m, setup, load_measurements(campaign / "iso-ind.csv", m, setup))
    assert isinstance(why, str) and "'indicators' instrument reads neither" in why


def test_identifiability_predicts_accuracy(campaign):
    res = _run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses",
               campaign / "poses.csv", "--accuracy", "--json")
    pred = json.loads(res.stdout)["predicted_accuracy"]
    assert pred["level"] == 0.95 and pred["points"] > 50
    assert 0 < pred["position_95_mm"]["median"] <= pred["position_95_mm"]["max"]
    assert len(pred["iso9283_cube"]["position_95_mm"]) == 5
    text = _run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses",
                campaign / "poses.csv", "--accuracy").stdout
    assert "predicted accuracy after calibrating on these poses" in text
    out = campaign / "map.png"
    _run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses", campaign / "poses.csv",
         "--accuracy", "--accuracy-map", out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    res = CliRunner().invoke(cli, ["identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses",
                                   str(campaign / "poses.csv"), "--accuracy-map", str(campaign / "never.png")])
    assert_user_error(res, "--accuracy-map", "--accuracy")
    assert not (campaign / "never.png").exists()


def test_no_platform_prediction_after_estimating_the_sensor():
    """A calibration that estimated sensor parameters (a tracker's target offset) keeps no
    machine-sensor covariance: the machine block alone would predict the gauge's platform
    origin (0.8 mm on the prototype with a laser tracker, against 11-20 um measured), so
    no prediction is printed, and the note says why."""
    from pkmcal.identification.iso9283 import _without_prediction

    C = np.eye(3)
    assert _without_prediction(C, {"sensor": {}, "std": {}}) == (C, ())
    cov, notes = _without_prediction(C, {"std": {"target.x": 0.1}})
    assert cov is None and "target.x" in notes[0] and "identifiability --accuracy" in notes[0]


def test_registration_std_carries_into_u():
    """A calibrated file whose instrument frame was estimated (setup.std of world.*, mm and
    degrees): with the frame at identity (K = I, ∂e/∂world.x = −1) U of AP_x is
    2 √(σ²/n + σ_wx²), world.a's std (degrees) enters AP_a in radians and AP_y as z·σ_wa;
    the tool offset's std does not enter (it defines the point commanded)."""
    from pkmcal.identification.iso9283 import cube_pattern, heldout_figures
    from pkmcal.io.measurements import Measurements

    m = load_machine("stewart-prototype")
    setup = load_setup_full_pose()
    pat = cube_pattern(m.home_pose[:3], 20.0, m.home_pose)
    cmd = np.tile(pat, (4, 1))
    rng = np.random.default_rng(0)
    y = cmd + rng.normal(scale=0.01, size=cmd.shape) * [1, 1, 1, 1e-3, 1e-3, 1e-3]
    meas = Measurements(m.ik(cmd), y, commanded=cmd)
    base = heldout_figures(m, setup, meas)
    got = heldout_figures(m, setup, meas, identified={"std": {"world.x": 0.02, "world.a": 0.01, "tool.y": 5.0},
                                                       "covariance_kind": "gls"})
    sig = setup.noise.reading_std
    ux = got.get("AP_x", "P1").U
    assert ux == pytest.approx(2 * math.sqrt(sig[0] ** 2 / 4 + 0.02 ** 2), rel=1e-6)
    assert base.get("AP_x", "P1").U == pytest.approx(2 * sig[0] / 2, rel=1e-6)
    ua = got.get("AP_a", "P1").U
    assert ua == pytest.approx(2 * math.sqrt(sig[3] ** 2 / 4 + np.deg2rad(0.01) ** 2), rel=1e-6)
    # the frame's rotation about x moves the points' y by z·δa, z the attained z (315 mm at P1
    # ± the readings' noise: 0.01/315 relative)
    uy = got.get("AP_y", "P1").U
    assert uy == pytest.approx(2 * math.sqrt(sig[1] ** 2 / 4 + (pat[0, 2] * np.deg2rad(0.01)) ** 2), rel=1e-4)
    same = heldout_figures(m, setup, meas, identified={"std": {"world.x": 0.02, "world.a": 0.01}})
    assert [f.U for f in same.figures] == pytest.approx([f.U for f in got.figures], rel=1e-12)   # tool.y: not carried
    assert "world.x, world.a" in got.uncertainty and "tool.y" not in got.uncertainty
    moved = Measurements(meas.actuators[1:], y[1:], commanded=cmd[1:])
    assert "not the ISO 9283 pattern" in heldout_figures(m, setup, moved)


def load_setup_full_pose():
    from pkmcal.api import load_setup

    return load_setup("full-pose-paper1", load_machine("stewart-prototype"))


def test_verify_reports_the_ballbar_circle(tmp_path):
    """A ballbar calibration, then its circle test (plan --algorithm circle) measured on the
    real machine: verify prints the ISO 230-4 figures, F_max the largest reading itself."""
    from pathlib import Path

    bar = Path(__file__).resolve().parents[2] / "examples" / "setup-ballbar.yaml"
    _run("plan", "stewart-prototype", "--setup", bar, "--n-poses", 60, "-o", tmp_path / "poses.csv")
    _run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", bar, "--poses",
         tmp_path / "poses.csv", "--seed", 4, "-o", tmp_path / "meas.csv")
    _run("identify", "stewart-prototype", tmp_path / "meas.csv", "--setup", bar, "-o", tmp_path / "cal.yaml")
    _run("plan", "stewart-prototype", "--setup", bar, "--algorithm", "circle", "--n-poses", 36, "-o", tmp_path / "circle.csv")
    _run("simulate", tmp_path / "cal.yaml", "--real", "stewart-prototype-real", "--setup", bar, "--poses",
         tmp_path / "circle.csv", "--seed", 5, "-o", tmp_path / "circle-meas.csv")
    res = _run("verify", tmp_path / "cal.yaml", "--held-out", tmp_path / "circle-meas.csv", "--setup",
               tmp_path / "cal.yaml", "--json")
    circle = json.loads(res.stdout)["iso230_4"]
    readings = read_table(tmp_path / "circle-meas.csv", ["dist1"], kinds={})["dist1"]
    by = {f["figure"]: f for f in circle["figures"]}
    assert by["F_max"]["value_mm"] == pytest.approx(readings.max(), abs=1e-12)
    assert by["F_min"]["value_mm"] == pytest.approx(readings.min(), abs=1e-12)
    assert by["F_max"]["U_mm"] == pytest.approx(2 * 0.001, rel=1e-12)      # the bar's sigma, one reading
    assert by["G"]["value_mm"] > 0 and by["G"]["U_mm"] > 0
    assert "iso9283" not in json.loads(res.stdout)
