"""``pkmcal simulate / identify / identifiability / verify`` on the redundantly actuated planar
machines of paper 3: the whole chain through files, checked independently (force balance of
the simulated equilibrium, gauge-invariant prediction of the real readings, tool errors),
and the error paths (exit code 2, one stderr line, nothing written)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error

from pkmcal.cli.main import cli
from pkmcal.identification.tool_errors import calibrated_sensor
from pkmcal.io import load_machine, read_table, save_machine
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import load_setup
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import builtin_machine
from pkmcal.mechanisms.statics import force_balance

CASE1_POSES = np.array([[0, 205], [-50, 170], [50, 170], [-50, 240], [50, 240], [0, 165], [0, 245], [-55, 205],
                        [55, 205], [-25, 185], [25, 225], [25, 185], [-25, 225]], dtype=float)
CASE2_POSES = np.array([[0, 230, 0], [-60, 210, 10], [60, 250, -10], [-30, 200, -15], [30, 260, 15], [-80, 240, 5],
                        [80, 220, -5], [10, 195, 20], [-10, 265, -20], [50, 230, 12], [-50, 230, -12],
                        [0, 250, 8]], dtype=float)
HELD1 = np.array([[10, 200], [-30, 230], [40, 180]], dtype=float)
HELD2 = np.array([[20, 240, 3], [-40, 215, -7], [70, 255, 9]], dtype=float)
#: real machines: the paper's Table 1 / Table 2 errors plus some more (mm, rad)
REAL1 = {"l11": 0.089, "l12": -0.244, "l22": -0.458, "B2.x": -0.547, "B3.y": -0.037, "D2": -0.029,
         "dq1": np.deg2rad(0.024), "dq3": np.deg2rad(-0.057)}
REAL2 = {"L3": 0.079, "rho11": -0.151, "rho12": -0.421, "rho21": 0.136, "alpha1": np.deg2rad(-0.065),
         "alpha2": np.deg2rad(0.035), "y2": 0.1, "dq2": 0.05}


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _ok(result):
    assert result.exit_code == 0, result.output + (result.stderr or "")
    return result


def _write_poses(path, machine, poses):
    path.write_text(format_table({n: poses[:, k] for k, n in enumerate(machine.pose_names)}))
    return path


def _files(tmp_path, case):
    """nominal, real (file), setup (file, noise-free), poses file, held-out poses file."""
    nominal = builtin_machine("planar-2dof-3act" if case == 1 else "planar-3dof-4act")
    real = nominal.with_deltas(REAL1 if case == 1 else REAL2, name=f"real{case}")
    save_machine(real, tmp_path / "real.yaml")
    k = "5.0e7" if case == 1 else "2.0e4"
    (tmp_path / "clean.yaml").write_text("sensor: planar-tool\ntarget: {x: 0.5, y: -0.25}\n"
                                         f"noise: {{reading: 0, actuator: 0}}\nsimulation: {{stiffness: {k}}}\n")
    poses = _write_poses(tmp_path / "poses.csv", nominal, CASE1_POSES if case == 1 else CASE2_POSES)
    held = _write_poses(tmp_path / "held.csv", nominal, HELD1 if case == 1 else HELD2)
    return nominal, real, tmp_path / "clean.yaml", poses, held


def _independent_rest_check(nominal, real, setup, meas):
    """The simulated readings belong to one real rest pose: the tracker reading gives the pose
    (closed form for n = 2, with the real machine's FK angle for n = 3), whose real IK is the
    encoder reading, and the actuator springs balance there (no load: Γᵀ K (q − c) = 0)."""
    q, y, cmd = meas.actuators, meas.readings, meas.commanded
    if nominal.n_dof == 2:
        x = real.poses_from_frame(setup.sensor.frame_for_readings(y, np.eye(3)))
    else:
        x = real.poses_from_frame(setup.sensor.frame_for_readings(y, real.frame(real.fk(q, guess=cmd).poses).R))
    np.testing.assert_allclose(real.ik(x), q, rtol=0, atol=1e-9)
    c = nominal.ik(cmd)
    assert np.max(np.abs(q - c)) > 1e-4                                       # real following errors
    K = setup.simulation.stiffness_for(real)
    g = force_balance(real, c, K, x)
    assert np.max(np.abs(g)) <= 1e-6 * np.max(K * np.abs(q - c))


def _predicts_real_readings(cal, cal_sens, real, sensor, held):
    """Gauge-invariant recovery: for real poses x, there is a calibrated-model pose x' whose
    calibrated IK and tracker prediction equal the real readings (≤ 1e-6 mm or rad)."""
    q, y = real.ik(held), sensor.predict(real.frame(held))
    x2 = cal.fk(q, guess=held).poses
    np.testing.assert_allclose(cal.ik(x2), q, rtol=0, atol=1e-6)
    np.testing.assert_allclose(cal_sens.predict(cal.frame(x2)), y, rtol=0, atol=1e-6)


@pytest.mark.parametrize("case", [1, 2])
def test_simulate_identify_verify_recovers_the_real_machine(tmp_path, case):
    nominal, real, setup_path, poses, held = _files(tmp_path, case)
    meas_path, cal_path = tmp_path / "meas.csv", tmp_path / "cal.yaml"
    _ok(run("simulate", nominal.name, "--real", tmp_path / "real.yaml", "--setup", setup_path, "--poses", poses,
            "--seed", 4, "-o", meas_path))
    header = [ln for ln in meas_path.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == ",".join(nominal.actuator_names + ("px", "py") + tuple(f"cmd_{p}" for p in nominal.pose_names))
    setup = load_setup(setup_path, nominal)
    meas = load_measurements(meas_path, nominal, setup)
    assert len(meas) == len(CASE1_POSES if case == 1 else CASE2_POSES)
    _independent_rest_check(nominal, real, setup, meas)

    out = _ok(run("identify", nominal.name, meas_path, "--setup", setup_path, "--unweighted", "-o", cal_path)).output
    assert "method projection (unweighted)" in out                           # the default for redundant machines
    cal = load_machine(cal_path)
    assert type(cal) is type(nominal)
    cal_sens = calibrated_sensor(cal, setup.sensor)
    _predicts_real_readings(cal, cal_sens, real, setup.sensor, np.vstack([HELD1 if case == 1 else HELD2]))
    if case == 2:                                                            # fully identifiable: the parameters
        np.testing.assert_allclose(cal.params, real.params, rtol=0, atol=1e-7)
        np.testing.assert_allclose(cal_sens.target, [0.5, -0.25], rtol=0, atol=1e-7)

    res = _ok(run("verify", cal_path, "--real", tmp_path / "real.yaml", "--setup", setup_path, "--poses", held,
                  "--nominal", nominal.name, "--json"))
    d = json.loads(res.output)
    assert d["after"]["poses"] == 3 and d["after"]["tool_max_mm"] <= 1e-6
    assert d["before"]["tool_mean_mm"] > 0.05
    assert (("angle_max_deg" in d["after"]) == (case == 2))
    table = _ok(run("verify", cal_path, "--real", tmp_path / "real.yaml", "--setup", setup_path, "--poses", held)).output
    assert "tool_mean_mm" in table and "held-out poses" in table


def test_verify_under_load_matches_the_equilibrium(tmp_path):
    """With a load the perfect model still misses by the compliance: the 'after' error of the
    real machine itself as the model equals the static deflection F/K of the tool point,
    computed here from the linearised statics (paper 3 eq. 1, 3) as an independent check."""
    from pkmcal.mechanisms.statics import linear_response

    nominal = builtin_machine("planar-3dof-4act")
    (tmp_path / "s.yaml").write_text("sensor: planar-tool\nnoise: {reading: 0, actuator: 0}\n"
                                     "simulation: {stiffness: 2.0e4, load: [0, -30]}\n")
    held = _write_poses(tmp_path / "held.csv", nominal, HELD2)
    res = _ok(run("verify", nominal.name, "--real", nominal.name, "--setup", tmp_path / "s.yaml", "--poses", held,
                  "--json"))
    d = json.loads(res.output)
    setup = load_setup(tmp_path / "s.yaml", nominal)
    held_internal = np.column_stack([HELD2[:, :2], np.deg2rad(HELD2[:, 2])])
    _, _, dP = linear_response(nominal, setup.sensor, held_internal, np.zeros(13), np.zeros(5), 2e4, load=[0, -30])
    expect = np.linalg.norm(dP, axis=1)
    np.testing.assert_allclose(d["after"]["tool_max_mm"], expect.max(), rtol=1e-3)
    assert 1e-5 < expect.max() < 1e-2


def test_random_errors_save_real_and_baselines(tmp_path):
    nominal = builtin_machine("planar-3dof-4act")
    poses = _write_poses(tmp_path / "poses.csv", nominal, CASE2_POSES)
    m1, m2, real_path = tmp_path / "m1.csv", tmp_path / "m2.csv", tmp_path / "real.yaml"
    _ok(run("simulate", nominal.name, "--random-errors", 0.2, "--save-real", real_path, "--setup",
            "planar-tracker", "--poses", poses, "--seed", 7, "-o", m1))
    real = load_machine(real_path)
    d = real.params - nominal.params
    ang = np.array(nominal.param_is_angle)
    assert np.all(np.abs(d[~ang]) <= 0.2) and np.all(np.abs(d[ang]) <= 0.2e-3) and np.any(np.abs(d[~ang]) > 0.05)
    # same seed, same bytes
    _ok(run("simulate", nominal.name, "--random-errors", 0.2, "--setup", "planar-tracker", "--poses", poses,
            "--seed", 7, "-o", m2))
    assert m1.read_bytes() == m2.read_bytes()
    for method, extra in (("projection", ()), ("ignore-redundancy", ()), ("actuator-subset", ("--keep", "1,3,4"))):
        cal = tmp_path / f"cal-{method}.yaml"
        out = _ok(run("identify", nominal.name, m1, "--setup", "planar-tracker", "--method", method, *extra,
                      "-o", cal, "--json")).output
        fit = json.loads(out[out.index("{"):])
        assert fit["method"] == method
        c = load_machine(cal)
        assert type(c) is type(nominal) and c.covariance is not None
        if method == "actuator-subset":                 # actuator 2 is not used: its leg and offset stay nominal
            assert set(fit["gauge"]) == {"rho12", "dq2"}
            assert c.p("rho12") == nominal.p("rho12") and c.p("dq2") == nominal.p("dq2")


def test_identifiability_of_a_planar_machine(tmp_path):
    nominal = builtin_machine("planar-2dof-3act")
    poses = _write_poses(tmp_path / "poses.csv", nominal, CASE1_POSES)
    d = json.loads(_ok(run("identifiability", nominal.name, "--setup", "planar-tracker", "--poses", poses,
                           "--json")).output)
    assert d["n_params"] == 20 and d["rank"] == 15 and len(d["null_space"]) == 5
    text = _ok(run("identifiability", nominal.name, "--setup", "planar-tracker", "--poses", poses)).output
    assert "rank 15 of 20" in text and "suggested gauge" in text


def test_planar_ik_uses_actuator_is_angle(tmp_path):
    nominal = builtin_machine("planar-2dof-3act")
    poses = _write_poses(tmp_path / "poses.csv", nominal, CASE1_POSES[:2])
    out = tmp_path / "q.csv"
    _ok(run("ik", nominal.name, "--poses", poses, "-o", out))
    t = read_table(out, ("q1", "q2", "q3"), kinds={})
    np.testing.assert_allclose(t.values, np.rad2deg(nominal.ik(CASE1_POSES[:2])), rtol=0, atol=1e-12)


def test_planar_error_paths(tmp_path):
    nominal, real, setup_path, poses, held = _files(tmp_path, 2)
    out = tmp_path / "out.csv"
    nosim = tmp_path / "nosim.yaml"
    nosim.write_text("sensor: planar-tool\nnoise: {reading: 0.01, actuator: 0.001}\n")
    assert_user_error(run("simulate", nominal.name, "--real", tmp_path / "real.yaml", "--setup", nosim,
                           "--poses", poses, "-o", out), "simulation:", "stiffness")
    assert_user_error(run("simulate", nominal.name, "--real", tmp_path / "real.yaml", "--setup", "laser-tracker",
                           "--poses", poses, "-o", out), "cannot measure", "planar-tool")
    assert_user_error(run("simulate", nominal.name, "--real", "planar-2dof-3act", "--setup", setup_path,
                           "--poses", poses, "-o", out), "not of the kind")
    bad_poses = tmp_path / "bad.csv"
    bad_poses.write_text("x,y\n0,230\n")
    assert_user_error(run("simulate", nominal.name, "--real", tmp_path / "real.yaml", "--setup", setup_path,
                           "--poses", bad_poses, "-o", out), "phi")
    assert not out.exists()
    _ok(run("simulate", nominal.name, "--real", tmp_path / "real.yaml", "--setup", setup_path, "--poses", poses,
            "-o", out))
    cal = tmp_path / "cal.yaml"
    assert_user_error(run("identify", nominal.name, out, "--setup", setup_path, "--method", "actuator-subset",
                           "--keep", "1,2", "-o", cal), "--keep", "3 different actuator numbers")
    assert_user_error(run("identify", nominal.name, out, "--setup", setup_path, "--keep", "1,2,3", "-o", cal),
                       "--keep")
    assert_user_error(run("identify", nominal.name, out, "--setup", setup_path, "--method", "actuator-subset",
                           "--keep", "a,b,c", "-o", cal), "actuator numbers")
    nocmd = tmp_path / "nocmd.csv"
    nocmd.write_text("\n".join(",".join(ln.split(",")[:6]) for ln in out.read_text().splitlines()
                               if not ln.startswith("#")) + "\n")
    assert_user_error(run("identify", nominal.name, nocmd, "--setup", setup_path, "--method", "ignore-redundancy",
                           "-o", cal), "cmd_")
    assert_user_error(run("identify", "stewart-prototype", out, "--setup", setup_path, "-o", cal), "cannot measure")
    assert not cal.exists()
    assert_user_error(run("verify", nominal.name, "--real", tmp_path / "real.yaml", "--poses", held),
                       "--setup")
    assert_user_error(run("verify", nominal.name, "--real", tmp_path / "real.yaml", "--poses", held, "--setup",
                           nosim), "simulation:")
    # for a non-redundant machine --setup is the true instrument (verify --compare sensor): it must fit the machine
    assert_user_error(run("verify", "stewart-prototype", "--real", "stewart-prototype", "--poses", held,
                           "--setup", setup_path), "cannot measure")


@pytest.mark.parametrize("sensor_kind", ["planar-tool", "position"])
def test_sensor_calibration_block_round_trip_by_declared_angles(tmp_path, sensor_kind):
    """``calibration.sensor`` of a machine file: the parameters the sensor declares angles
    (``param_is_angle``: planar world.c; position world.a, b, c) in degrees, the rest in mm;
    written, saved with the machine, loaded and applied, it gives back the same radians."""
    import dataclasses

    from pkmcal.identification.tool_errors import sensor_calibration_block
    from pkmcal.sensors import PlanarToolSensor, PositionSensor

    if sensor_kind == "planar-tool":
        base = PlanarToolSensor(n_pose=3)
        theta = np.array([0.5, -0.25, 12.0, -3.0, np.deg2rad(0.7)])
    else:
        base = PositionSensor()
        theta = np.array([1.0, 2.0, 30.0, -4.0, 5.0, 6.0, *np.deg2rad([0.3, -1.1, 2.5])])
    sensor = base.with_params(theta)
    block = sensor_calibration_block(sensor)
    assert list(block) == list(sensor.param_names)
    for name, value, is_angle in zip(sensor.param_names, theta, sensor.param_is_angle):
        assert block[name] == pytest.approx(value * 180.0 / np.pi if is_angle else value, rel=1e-15), name
    machine = builtin_machine("planar-3dof-4act")
    machine = dataclasses.replace(machine, metadata={**dict(machine.metadata), "calibration": {"sensor": block}})
    save_machine(machine, tmp_path / "cal.yaml")
    back = calibrated_sensor(load_machine(tmp_path / "cal.yaml"), base)
    np.testing.assert_allclose(back.params, theta, rtol=1e-15, atol=0)
    assert calibrated_sensor(builtin_machine("planar-3dof-4act"), base) is base     # no record: unchanged
