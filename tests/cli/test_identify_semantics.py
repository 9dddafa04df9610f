"""``pkmcal identify`` / ``identifiability`` / ``observability`` / ``verify`` never print a
quietly wrong answer (issue 10 items 4 and 7). Each test names the old behaviour it fails on.
Data are simulated with fixed seeds (the campaign's noise from ``--seed``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.measurements import load_measurements
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.sensors.library import builtin_setup

POSE_NAMES = ("x", "y", "z", "a", "b", "c")
HALF = np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])  # mm, deg: all reachable by both machines
SIM = ("simulate", "stewart-prototype", "--real", "stewart-prototype-real")

INDICATORS_ZEROS_FREE = """\
sensor: indicators
indicators: [[40.0, 0.0], [-20.0, 34.64101615137754], [-20.0, -34.64101615137754]]
plane_offset: 10.0
free: [zero1, zero2, zero3]
noise: {reading: 0.01, actuator: 0.005}
"""


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


def write_poses(path, poses_file_units) -> None:
    path.write_text(format_table({k: poses_file_units[:, i] for i, k in enumerate(POSE_NAMES)}))


def random_poses(n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 6)) * HALF
    p[:, :3] += stewart_prototype().home_pose[:3]
    return p


def simulated(tmp_path, setup, poses, name="m.csv", seed=0):
    write_poses(tmp_path / "poses.csv", poses)
    ok(run(*SIM, "--setup", setup, "--poses", tmp_path / "poses.csv", "--seed", seed, "-o", tmp_path / name))
    return tmp_path / name


def test_identify_and_identifiability_agree_on_a_pure_z_pose_set(tmp_path):
    """Old behaviour: identifiability said rank 9 of 42, identify judged the rank on the
    noisy measured poses (rank 36-38) and printed that many parameters with σ up to 1e7 mm.
    Now both judge the plan (the commanded poses) and the fit estimates the 9 combinations.
    The 9 combinations do not explain the real prototype's readings (χ²/E[χ²] ~ 1e6): since
    issue 24 such a fit is refused, so it is written here with --accept-bad-fit."""
    z = np.linspace(290.0, 340.0, 20)
    poses = np.zeros((20, 6))
    poses[:, 2] = z
    meas = simulated(tmp_path, "indicators-prototype", poses)
    ident = json.loads(ok(run("identifiability", "stewart-prototype", "--setup", "indicators-prototype",
                              "--poses", tmp_path / "poses.csv", "--json")).stdout)
    fit = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", "indicators-prototype",
                            "-o", tmp_path / "cal.yaml", "--json", "--accept-bad-fit")).stdout)
    assert not fit["verdict"]["acceptable"]
    assert ident["rank"] == fit["identifiability"]["rank"] == 9
    assert len(fit["free"]) == 9
    assert "commanded poses" in fit["identifiability"]["basis"]
    assert any(w.startswith("warning: weakly identifiable direction") for w in fit["warnings"])


def test_free_adds_to_the_setup_free_list(tmp_path):
    """Old behaviour: --free replaced the setup's free: list, so the indicator zeros the
    setup frees were silently held at 0."""
    (tmp_path / "setup.yaml").write_text(INDICATORS_ZEROS_FREE)
    meas = simulated(tmp_path, tmp_path / "setup.yaml", random_poses(40, 1))
    res = ok(run("identify", "stewart-prototype", meas, "--setup", tmp_path / "setup.yaml", "--free", "b*,a*,L0_*",
                 "--fix", "auto", "-o", tmp_path / "cal.yaml", "--json"))
    d = json.loads(res.stdout)
    assert {"zero1", "zero2", "zero3"} <= set(d["free"]) | set(d["gauge"])
    assert "zero1 (setup free:)" in d["free_rule"] and "does not replace" in d["free_rule"]
    table = ok(run("identify", "stewart-prototype", meas, "--setup", tmp_path / "setup.yaml", "--free", "b*,a*,L0_*",
                   "--fix", "auto", "-o", tmp_path / "cal.yaml")).stdout
    assert "free parameters:" in table and "(setup free:)" in table


def test_free_names_a_sensor_parameter_the_setup_holds(tmp_path):
    """The other direction: the built-in indicators setup frees no zero; --free naming zero1
    frees that one (stated as coming from --free) and only it."""
    meas = simulated(tmp_path, "indicators-prototype", random_poses(40, 2))
    d = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", "indicators-prototype", "--free",
                          "b*,a*,L0_*,zero1", "--fix", "auto", "-o", tmp_path / "cal.yaml", "--json")).stdout)
    sensor_free = {n for n in d["free"] if n.startswith("zero")} | {n for n in d["gauge"] if n.startswith("zero")}
    assert sensor_free == {"zero1"}
    assert "zero1 (--free)" in d["free_rule"] or "zero1" in d["gauge"]


def test_a_fit_without_degrees_of_freedom_is_refused(tmp_path):
    """Old behaviour: a one-pose fit (3 readings, the gauge fixing the rest) was written as a
    calibrated machine."""
    meas = simulated(tmp_path, "indicators-prototype", random_poses(1, 3))
    res = run("identify", "stewart-prototype", meas, "--setup", "indicators-prototype", "-o", tmp_path / "cal.yaml")
    assert res.exit_code == 2, res.output
    assert "no degree of freedom" in res.stderr and "nothing written" in res.stderr
    assert not (tmp_path / "cal.yaml").exists()


def test_radian_angle_columns_and_absurd_chi2_are_warned(tmp_path):
    """Old behaviour: angles written in radians under degree headers calibrated to
    parameters metres off with only χ²/ν in the summary as a hint. Now refused (issue 24:
    tests/identification/test_fit_verdict.py); written with --accept-bad-fit, the warnings name the columns."""
    meas = simulated(tmp_path, "full-pose-paper1", random_poses(30, 4))
    lines = meas.read_text().splitlines()
    header_i = next(i for i, ln in enumerate(lines) if ln.startswith("lambda1"))
    cols = lines[header_i].split(",")
    angle_k = [cols.index(c) for c in ("a", "b", "c")]
    for i in range(header_i + 1, len(lines)):
        cells = lines[i].split(",")
        for k in angle_k:
            cells[k] = repr(float(np.deg2rad(float(cells[k]))))
        lines[i] = ",".join(cells)
    bad = tmp_path / "radians.csv"
    bad.write_text("\n".join(lines) + "\n")
    refused = run("identify", "stewart-prototype", bad, "--setup", "full-pose-paper1", "-o", tmp_path / "cal.yaml")
    assert refused.exit_code == 2 and refused.stderr.count("looks like radians") == 3, refused.output
    d = json.loads(ok(run("identify", "stewart-prototype", bad, "--setup", "full-pose-paper1",
                          "-o", tmp_path / "cal.yaml", "--json", "--accept-bad-fit")).stdout)
    assert sum(w.startswith("warning: column") and "looks like radians" in w for w in d["warnings"]) == 3
    assert not d["verdict"]["acceptable"]
    # the same file in degrees: no such warning
    good = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", "full-pose-paper1",
                             "-o", tmp_path / "cal2.yaml", "--json")).stdout)
    assert not any("radians" in w or "chi2/" in w for w in good["warnings"])


def test_absurd_chi2_is_warned(tmp_path):
    """Readings 100× noisier than the setup says (χ²/ν ~ 10⁴): old behaviour, only the χ²/ν
    figure in the summary; now refused, and with --accept-bad-fit written with a warning
    naming the likely causes. A χ²/ν near 1 is not."""
    meas = simulated(tmp_path, "indicators-prototype", random_poses(40, 8))
    (tmp_path / "tight.yaml").write_text(INDICATORS_ZEROS_FREE.replace("free: [zero1, zero2, zero3]\n", "")
                                         .replace("reading: 0.01, actuator: 0.005", "reading: 0.0001, actuator: 5e-05"))
    refused = run("identify", "stewart-prototype", meas, "--setup", tmp_path / "tight.yaml", "-o", tmp_path / "cal.yaml")
    assert refused.exit_code == 2 and "noise far too small" in refused.stderr, refused.output
    d = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", tmp_path / "tight.yaml",
                          "-o", tmp_path / "cal.yaml", "--json", "--accept-bad-fit")).stdout)
    assert d["reduced_chi2"] > 1000
    assert any(w.startswith("warning: chi2/E[chi2]") and "units" in w and "noise" in w for w in d["warnings"])
    good = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", "indicators-prototype",
                             "-o", tmp_path / "cal2.yaml", "--json")).stdout)
    assert 0.5 < good["reduced_chi2"] < 2 and not any("chi2/" in w for w in good["warnings"])


def test_residual_figures_say_what_they_are(tmp_path):
    """Old behaviour: one 'rms residual' over rows in mm and rad, and no solver cost, so the
    two could not be compared. Now: rms per unit (checked against NumPy on the engine's
    residuals), χ² with the weights at the solution, the cost with the start weights."""
    nominal, real = stewart_prototype(), stewart_prototype().with_params(stewart_prototype().params + 0.3)
    setup = builtin_setup("full-pose-paper1")
    poses = nominal.home_pose + np.random.default_rng(5).uniform(-1, 1, (30, 6)) * np.r_[HALF[:3],
                                                                                           np.deg2rad(HALF[3:])]
    sim = simulate_campaign(nominal, real, setup, poses, rng=1, ignore_limits=("leg_collision",))
    res = identify(nominal, setup, sim.measurements, method="fk-residual")
    r = res.residuals
    rms = res.rms_by_unit()
    assert rms["mm"] == pytest.approx(np.sqrt(np.mean(r[:, :3] ** 2)), rel=1e-12)
    assert rms["deg"] == pytest.approx(np.rad2deg(np.sqrt(np.mean(r[:, 3:] ** 2))), rel=1e-12)
    assert res.rms_whitened == pytest.approx(np.sqrt(res.uncertainty.chi2 / r.size), rel=1e-12)
    d = res.to_dict()
    assert d["residual_rms_mm"] == rms["mm"] and d["residual_rms_deg"] == rms["deg"]
    assert "start" in d["units"]["cost"] and "solution" in d["units"]["chi2"]
    assert d["units"]["rms_residual"].startswith("mixed")


def test_default_method_is_the_same_everywhere(tmp_path):
    """Old behaviour: identify defaulted to ik-residual for a full-pose sensor,
    identifiability to fk-residual, the engine's identify() to fk-residual."""
    poses = random_poses(20, 6)
    meas = simulated(tmp_path, "full-pose-paper1", poses)
    ident = json.loads(ok(run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1",
                              "--poses", tmp_path / "poses.csv", "--json")).stdout)
    fit = json.loads(ok(run("identify", "stewart-prototype", meas, "--setup", "full-pose-paper1",
                            "-o", tmp_path / "cal.yaml", "--json")).stdout)
    assert ident["basis"].startswith("ik-residual") and fit["method"] == "ik-residual"
    nominal, setup = stewart_prototype(), builtin_setup("full-pose-paper1")
    api = identify(nominal, setup, load_measurements(meas, nominal, setup))
    assert api.method == "ik-residual"


def test_unreachable_poses_are_warned(tmp_path):
    """Old behaviour: observability and identifiability of poses the machine cannot take
    printed numbers without a word."""
    poses = random_poses(12, 7)
    poses[5, 0] = 200.0
    write_poses(tmp_path / "p.csv", poses)
    res = ok(run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses", tmp_path / "p.csv"))
    assert "violate the machine's limits" in res.stdout and "rows 6 (data rows, 1-based)" in res.stdout
    d = json.loads(ok(run("identifiability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses",
                          tmp_path / "p.csv", "--json")).stdout)
    assert any("rows 6" in w for w in d["warnings"])
    res = ok(run("observability", "stewart-prototype", tmp_path / "p.csv", "--setup", "full-pose-paper1"))
    assert "violate the machine's limits" in res.stdout


def test_planar_verify_with_nothing_reached_is_an_error(tmp_path):
    """Old behaviour: a table of nan, exit 0."""
    (tmp_path / "held.csv").write_text("x,y\n900,900\n-900,900\n")
    res = run("verify", "planar-2dof-3act", "--real", "planar-2dof-3act", "--poses", tmp_path / "held.csv",
              "--setup", "planar-tracker", "--nominal", "planar-2dof-3act")
    assert res.exit_code == 2, res.output
    assert "none of the 2 held-out poses" in res.stderr
