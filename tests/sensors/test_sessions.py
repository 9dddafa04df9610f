"""Several measurement sessions in one fit (issue 11 item 7, :mod:`pkmcal.sensors.sessions`).

Data are simulated here independently of the engine: each session's readings come from
its own true sensor, and re-homed sessions from the real machine's FK at q + δq while the
readings record q. Checks: noise-free recovery of the shared machine and of two different
session frames (full-pose and position sensors, every method), of the re-homing offsets,
the shared gauge, analytic Jacobians (session sensor and every method with offsets)
against central differences, the session column of the CSV (read, written, read by pandas
and csv, errors naming the line), the setup's ``sessions:`` key, rejection keeping the
file's pose numbers, and ``pkmcal simulate --sessions``.
"""

from __future__ import annotations

import csv
import json
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_jacobian_matches_fd, fuzz_settings, random_poses
from hypothesis import given
from hypothesis import strategies as st
from test_engine import _fd_model, nominal, real  # noqa: F401  (fixtures: the prototype and its real twin)

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.residuals import Model, make_method
from pkmcal.io.measurements import Measurements, load_measurements, save_measurements
from pkmcal.io.setup_file import load_setup
from pkmcal.sensors.base import MeasurementSetup, NoiseModel
from pkmcal.sensors.full_pose import FullPoseSensor
from pkmcal.sensors.position import PositionSensor
from pkmcal.sensors.sessions import Sessions, SessionSensor, sensor_from_values, session_setup_values, setup_values

NOISE_FULL = NoiseModel(reading_std=np.array([0.01] * 3 + [1e-4] * 3), actuator_std=np.full(6, 0.005))
NOISE_3 = NoiseModel(reading_std=np.full(3, 0.01), actuator_std=np.full(6, 0.005))
#: Two different true world frames (pose of the base in the sensor frame, mm and rad) and
#: the tool/target offsets.
WORLDS = ([10.0, -5.0, 2.0, 0.01, -0.02, 0.03], [-20.0, 7.0, -3.0, -0.03, 0.01, 0.2])
TOOL = [1.0, 2.0, 30.0, 0.0, 0.01, 0.0]
TARGET = [5.0, -3.0, 20.0]
#: Re-homing offsets of session 2 (mm).
DQ2 = np.array([0.3, -0.2, 0.1, 0.05, -0.4, 0.25])
WORLD = tuple(f"world.{c}" for c in "xyzabc")


def true_sensors(kind):
    if kind == "full-pose":
        return tuple(FullPoseSensor(world=w, tool=TOOL) for w in WORLDS)
    return tuple(PositionSensor(target=TARGET, world=w) for w in WORLDS)


def start_setup(kind):
    """The sensor the fit starts from: world frames unknown (zero), the tool/target near."""
    if kind == "full-pose":
        return MeasurementSetup(FullPoseSensor(tool=[0.0, 0.0, 30.0, 0.0, 0.01, 0.0],
                                               free=WORLD + ("tool.x", "tool.y", "tool.z")), NOISE_FULL)
    return MeasurementSetup(PositionSensor(target=[0.0, 0.0, 20.0], free=WORLD + ("target.x", "target.y", "target.z")),
                            NOISE_3)


def two_sessions(nominal, real, sensors, n=40, dq2=None, seed=0):
    """(q, y, commanded, labels): n poses, the first half session "A", the rest "B" read by
    ``sensors[1]`` (labels "A", "B" so that nothing depends on labels being numbers);
    session B re-homed by ``dq2``: the real machine at FK(q + dq2), the readings q."""
    cmd = random_poses(nominal, n, seed)
    q = nominal.ik(cmd)
    half = n // 2
    moved = q.copy()
    if dq2 is not None:
        moved[half:] += dq2
    fk = real.fk(moved, guess=cmd)
    assert fk.all_converged
    frames = real.frame(fk.poses)
    y = np.vstack([sensors[0].predict(frames[:half]), sensors[1].predict(frames[half:])])
    return q, y, cmd, ["A"] * half + ["B"] * (n - half)


def gauge_at_truth(nominal, real, setup, q, y, cmd, labels, method, **kw):
    """Fit once to find the gauge, then fit from a nominal machine whose gauge parameters
    have their true values, the gauge held: every other estimate must be the truth."""
    first = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method, sessions=labels, **kw)
    p = nominal.params
    for name in first.gauge:
        k = nominal.param_names.index(name)
        p[k] = real.params[k]
    start = nominal.with_params(p)
    free = [n for n in first.names if n not in first.gauge and (n in first.free or n in nominal.param_names)]
    return first, identify(start, setup, q=q, y=y, commanded=cmd, method=method, sessions=labels, free=free, **kw)


CASES = [("full-pose", "ik-residual"), ("full-pose", "fk-residual"), ("full-pose", "projection"),
         ("position", "fk-residual"), ("position", "projection")]


@pytest.mark.parametrize("kind,method", CASES)
def test_noise_free_recovery_of_machine_and_two_session_frames(nominal, real, kind, method):
    sensors = true_sensors(kind)
    setup = start_setup(kind)
    q, y, cmd, labels = two_sessions(nominal, real, sensors)
    first, res = gauge_at_truth(nominal, real, setup, q, y, cmd, labels, method)
    assert res.success
    est = dict(zip(res.names, res.estimate))
    # machine: every parameter the real machine's, 1e-9 mm
    np.testing.assert_allclose(res.estimate[:len(real.params)], real.params, rtol=0, atol=1e-9)
    # each session its own frame: 1e-9 mm, angles 1e-9 mm at 1 m
    for lab, s in zip("AB", sensors):
        for name, value, ang in zip(s.param_names, s.params, s.param_is_angle):
            assert abs(est[f"{name}@{lab}"] - value) <= (1e-12 if ang else 1e-9), (name, lab)
    # the two sessions' frames differ by far more than the tolerance: two frames were fitted
    assert abs(est["world.x@A"] - est["world.x@B"]) > 10.0
    # names: NAME@LABEL with sessions, no parameter without a label
    assert all("@" in n for n in res.names[len(nominal.param_names):])
    assert res.sessions.labels == ("A", "B")


def test_one_shared_gauge(nominal, real):
    """Two sessions, each with a free world frame: the base frame's gauge is shared (as many
    gauge parameters as with one session: moving the base moves every session's world)."""
    sensors = true_sensors("full-pose")
    setup = start_setup("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors)
    two = identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=labels)
    one = identify(nominal, setup, q=q[:20], y=y[:20], commanded=cmd[:20])
    assert len(two.gauge) == len(one.gauge) == 9
    assert not any("@" in n for n in two.gauge)
    assert two.identifiability.rank == two.identifiability.n_params - 9


@pytest.mark.parametrize("method", ["ik-residual", "fk-residual", "projection"])
def test_rehoming_offsets_recovered(nominal, real, method):
    sensors = true_sensors("full-pose")
    setup = start_setup("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors, dq2=DQ2)
    _, res = gauge_at_truth(nominal, real, setup, q, y, cmd, labels, method, session_offsets=True)
    names = [f"dq_{i + 1}@B" for i in range(6)]
    assert res.names[-6:] == tuple(names)
    np.testing.assert_allclose(res.estimate[-6:], DQ2, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.estimate[:len(real.params)], real.params, rtol=0, atol=1e-9)
    # offsets against L0: identifiable with two sessions (no offset in the gauge), and
    # the first session has none (its zeros are the machine's)
    assert not any(n.startswith("dq_") for n in res.gauge)
    assert not any(n.endswith("@A") and n.startswith("dq_") for n in res.names)
    # reported in the session values, file units
    np.testing.assert_allclose(res.session_values()["B"]["dq"], DQ2, atol=1e-9)
    # without offsets the re-homed data cannot be fitted: the model misses them
    plain = identify(nominal, setup, q=q, y=y, commanded=cmd, method=method, sessions=labels)
    assert plain.rms_residual > 1e-3


def test_squared_form_with_offsets(nominal, real):
    sensors = true_sensors("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors, dq2=DQ2)
    _, res = gauge_at_truth(nominal, real, start_setup("full-pose"), q, y, cmd, labels, "ik-residual",
                            session_offsets=True, form="squared")
    np.testing.assert_allclose(res.estimate[-6:], DQ2, rtol=0, atol=1e-8)


def test_one_session_has_no_offsets_and_no_labels(nominal, real):
    """A session column with one label, with offsets asked: names exactly as without sessions."""
    sensors = true_sensors("full-pose")
    q, y, cmd, _ = two_sessions(nominal, real, (sensors[0], sensors[0]))
    setup = start_setup("full-pose")
    a = identify(nominal, setup, q=q, y=y, commanded=cmd)
    b = identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=["only"] * len(q), session_offsets=True)
    assert a.names == b.names and not any("@" in n for n in b.names)
    np.testing.assert_array_equal(a.estimate, b.estimate)
    assert b.session_values() == {} and "sessions" not in b.to_dict()


# -- analytic Jacobians against central differences -------------------------------------


def test_session_sensor_jacobians_match_finite_differences(nominal):
    """The session sensor's ∂y/∂θ (block diagonal) and ∂y/∂twist against differences, with
    the sessions interleaved (index arrays, not slices)."""
    sensors = (PositionSensor(target=TARGET, world=WORLDS[0]), PositionSensor(target=[1.0, 2.0, 25.0], world=WORLDS[1]))
    ses = Sessions.from_labels(["1", "2", "1", "2", "2", "1"])
    ss = SessionSensor(sensors, ses)
    x = random_poses(nominal, 6, 4)
    frame = nominal.frame(x)
    theta = ss.params
    assert_jacobian_matches_fd(lambda t: ss.predict(frame, t), theta, ss.param_jacobian(frame),
                               scale=np.where(ss.param_is_angle, 1.0, 100.0), names=ss.param_names)
    # per pose it is the session's own sensor
    for k, g in enumerate(ses.groups):
        np.testing.assert_array_equal(ss.predict(frame)[g], sensors[k].predict(frame[g]))
        np.testing.assert_array_equal(ss.frame_jacobian(frame)[g], sensors[k].frame_jacobian(frame[g]))


@pytest.mark.parametrize("method,form", [("ik-residual", "plain"), ("ik-residual", "squared"),
                                         ("fk-residual", "plain")])
def test_method_jacobians_with_sessions_and_offsets(nominal, real, method, form):
    """Every column (machine, both sessions' sensors, offsets) at a perturbed point with
    noisy data; the offsets are lengths (mm) entering as the actuator readings do."""
    sensors = true_sensors("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors, n=8, dq2=DQ2)
    e_y, e_q = NOISE_FULL.sample(np.random.default_rng(2), y.shape, q.shape)
    base = FullPoseSensor(world=WORLDS[0], tool=TOOL)
    ses = Sessions.from_labels(labels, offsets=True)
    model = Model(nominal, SessionSensor.start(base, ses), NOISE_FULL, q + e_q, y + e_y, cmd, ses)
    meth = make_method(method, model, form=form)
    rng = np.random.default_rng(3)
    theta = model.theta0 + rng.normal(0, 0.3, model.theta0.size) * np.r_[
        np.where([n.startswith("gain_") for n in nominal.param_names], 0.01, 1.0),   # gains ~1 ± 0.003
        0.01 * np.ones(model.n_sensor), np.ones(model.n_offsets)]
    ev = meth.evaluate(theta)
    fd_model, _ = _fd_model(model, method, form, ev.poses)
    n_off = model.n_offsets
    for key in ("scale", "noise", "resolution"):     # offsets: as the machine's length columns
        v = np.broadcast_to(fd_model[key], (theta.size - n_off,))
        fd_model[key] = np.r_[v, np.full(n_off, v[0])]
    size = np.max(np.abs(ev.J).reshape(-1, ev.J.shape[-1]), axis=0)
    assert_jacobian_matches_fd(lambda t: meth.evaluate(t, jac=False, cov=False).r, theta, ev.J, slope=2.0 * size,
                               names=model.names, **fd_model)


def test_projection_jacobian_with_offsets(nominal, real):
    """Projection at a noise-free solution (the dropped derivative of U⊥ multiplies e = 0):
    the offset columns U⊥ᵀ W [0; I] against differences."""
    sensors = true_sensors("position")
    q, y, cmd, labels = two_sessions(nominal, nominal, sensors, n=8, dq2=DQ2)
    ses = Sessions.from_labels(labels, offsets=True)
    model = Model(nominal, SessionSensor(sensors, ses), NOISE_3, q, y, cmd, ses)
    meth = make_method("projection", model)
    theta = model.theta0.copy()
    theta[-6:] = DQ2
    ev = meth.evaluate(theta)
    assert np.max(np.abs(ev.r)) < 1e-8
    fd_model, _ = _fd_model(model, "fk-residual", "plain", ev.poses)
    M = max(np.abs(y / model.sigma_y).max(), np.abs(q / model.sigma_q).max())
    n_off = model.n_offsets
    scale = np.broadcast_to(fd_model["scale"], (theta.size - n_off,))
    size = np.max(np.abs(ev.J).reshape(-1, ev.J.shape[-1]), axis=0)
    assert_jacobian_matches_fd(lambda t: meth.evaluate(t, jac=False, cov=False).r, theta, ev.J, slope=2.0 * size,
                               scale=np.r_[scale, np.full(n_off, scale[0])], magnitude=M,
                               noise=32 * np.finfo(float).eps * M, names=model.names)


# -- files -------------------------------------------------------------------------------


def test_session_column_round_trip_and_default_readers(nominal, real, tmp_path):
    sensors = true_sensors("full-pose")
    setup = start_setup("full-pose")
    q, y, cmd, _ = two_sessions(nominal, real, sensors, n=10)
    labels = ["2026-05-01-am"] * 3 + ["pm 2"] * 4 + ["2026-05-01-am"] * 3
    meas = Measurements(actuators=q, readings=y, commanded=cmd, sessions=labels)
    path = tmp_path / "m.csv"
    save_measurements(path, meas, nominal, setup)
    back = load_measurements(path, nominal, setup)
    assert back.sessions.labels == ("2026-05-01-am", "pm 2")       # order of first appearance
    assert [back.sessions.labels[k] for k in back.sessions.index] == labels
    np.testing.assert_array_equal(back.actuators, q)
    # pandas and csv with their defaults: the documented columns, labels as written
    import pandas

    df = pandas.read_csv(path)
    assert list(df.columns)[0] == "lambda1" and list(df.columns)[-1] == "session" and list(df["session"]) == labels
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["session"] for r in rows] == labels and float(rows[0]["lambda1"]) == q[0, 0]
    # a subset keeps each pose's session and its file pose number
    sub = back.subset(np.array([0, 4, 9]))
    assert [sub.sessions.labels[k] for k in sub.sessions.index] == ["2026-05-01-am", "pm 2", "2026-05-01-am"]
    assert list(sub.pose_numbers) == [1, 5, 10]


def test_empty_session_label_names_the_line(nominal, real, tmp_path):
    sensors = true_sensors("full-pose")
    setup = start_setup("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors, n=4)
    path = tmp_path / "m.csv"
    save_measurements(path, Measurements(q, y, cmd, sessions=labels), nominal, setup, comments=("a comment",),
                      units_comment=True)
    lines = path.read_text().splitlines()
    assert lines[0].startswith("# units") and lines[3].endswith(",session")
    lines[5] = lines[5].rsplit(",", 1)[0] + ",  "          # the second data row, line 6
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(InputFileError, match=r"m\.csv, line 6, column 'session': empty session label"):
        load_measurements(path, nominal, setup)
    # the command line: exit code 2, one line
    res = CliRunner().invoke(cli, ["identify", "stewart-prototype", str(path), "--setup", "full-pose-paper1",
                                   "-o", str(tmp_path / "cal.yaml")])
    assert res.exit_code == 2 and "line 6" in res.output and "empty session label" in res.output


def test_setup_sessions_key(nominal, real, tmp_path):
    text = ("sensor: full-pose\ntool: {z: 30, b: 0.5729577951308232}\n"
            "free: [world.x, world.y, world.z, world.a, world.b, world.c, tool.x, tool.y, tool.z]\n"
            "noise: {position: 0.01, orientation_deg: 0.0057, actuator: 0.005}\n"
            "sessions:\n  actuator_offsets: true\n  'B': {world: {x: -20, c: 11.4591559026}, dq: [0, 0, 0, 0, 0, 0]}\n")
    p = tmp_path / "setup.yaml"
    p.write_text(text)
    setup = load_setup(p)
    assert setup.session_offsets is True
    (label, sensor), = setup.session_sensors
    assert label == "B" and sensor.world[0] == -20.0 and sensor.world[5] == pytest.approx(0.2, abs=1e-12)
    assert sensor.tool[2] == 30.0                             # not given: the setup's own
    q, y, cmd, labels = two_sessions(nominal, real, true_sensors("full-pose"), dq2=DQ2)
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=labels)
    assert res.names[-1] == "dq_6@B"
    assert res.initial[res.names.index("world.x@B")] == -20.0   # the named session starts from its values
    assert res.rms_residual < 1e-9
    for bad, what in (("  actuator_offsets: 1\n", "true or false"), ("  '2': {wrld: {x: 1}}\n", "wrld"),
                      ("  '2': {world: {x: yes}}\n", "finite number")):
        p.write_text(text.split("sessions:")[0] + "sessions:\n" + bad)
        with pytest.raises(InputFileError, match=what) as info:
            load_setup(p)
        assert "line 6" in str(info.value)


def test_setup_values_round_trip():
    s = FullPoseSensor(world=WORLDS[1], tool=TOOL)
    values = setup_values(s)
    assert values["world"]["c"] == pytest.approx(np.rad2deg(0.2))
    assert sensor_from_values(FullPoseSensor(), values) == s or np.allclose(
        sensor_from_values(FullPoseSensor(), values).params, s.params, rtol=0, atol=1e-15)
    ses = SessionSensor((s, FullPoseSensor()), Sessions.from_labels(["1", "2"]))
    out = session_setup_values(ses, {"2": DQ2})
    assert list(out) == ["1", "2"] and out["2"]["dq"] == list(DQ2) and "dq" not in out["1"]


def test_free_and_fix_names_without_label_mean_every_session(nominal, real):
    q, y, cmd, labels = two_sessions(nominal, real, true_sensors("full-pose"))
    setup = start_setup("full-pose")
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=labels, fix=["world.c", "b1.*", "a1.*", "b2.x",
                                                                                 "b2.z", "b3.z"])
    assert "world.c@A" in res.fixed and "world.c@B" in res.fixed and "world.x@B" in res.free
    with pytest.raises(PkmcalError, match="no parameter matches 'world.q'"):
        identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=labels, fix=["world.q"])


def test_rejection_keeps_file_pose_numbers(nominal, real, tmp_path):
    """A 5 mm outlier in session B: flagged and rejected under its file pose number; the
    refit without it is the clean one."""
    sensors = true_sensors("full-pose")
    setup = start_setup("full-pose")
    q, y, cmd, labels = two_sessions(nominal, real, sensors, n=60)
    e_y, e_q = NOISE_FULL.sample(np.random.default_rng(9), y.shape, q.shape)
    y, q = y + e_y, q + e_q
    y[44, 0] += 5.0
    path = tmp_path / "m.csv"
    save_measurements(path, Measurements(q, y, cmd, sessions=labels), nominal, setup)
    meas = load_measurements(path, nominal, setup).subset(np.arange(1, 60))   # pose 1 left out first
    res = identify(nominal, setup, meas, reject=4.0)
    assert [o.pose for o in res.screening.rejected] == [45]
    assert list(res.sessions.counts()) == [29, 29]
    clean = identify(nominal, setup, meas.subset(np.flatnonzero(meas.pose_numbers != 45)))
    np.testing.assert_allclose(res.estimate, clean.estimate, rtol=0, atol=1e-9)
    d = res.to_dict()
    assert d["outliers"][0]["pose"] == 45 and d["sessions"]["n_poses"] == {"A": 29, "B": 29}


# -- the command line ---------------------------------------------------------------------


def _poses_csv(path, n=30):
    rng = np.random.default_rng(0)
    p = np.c_[rng.uniform(-10, 10, (n, 2)), 330 + rng.uniform(-5, 5, (n, 1)), rng.uniform(-4, 4, (n, 3))]
    np.savetxt(path, p, delimiter=",", header="x,y,z,a,b,c", comments="")


def test_simulate_sessions_then_identify(tmp_path):
    """simulate --sessions 2 with re-homing: a session column, two different true frames
    listed; identify --session-offsets fits them (noise-free: residuals at rounding) and
    --json gives each session's values."""
    setup = tmp_path / "setup.yaml"
    setup.write_text("sensor: full-pose\ntool: {z: 30}\nfree: [world.x, world.y, world.z, world.a, world.b, world.c]\n"
                     "noise: {position: 0, orientation_deg: 0, actuator: 0}\n")
    fit_setup = tmp_path / "fit.yaml"
    fit_setup.write_text(setup.read_text().replace("position: 0, orientation_deg: 0, actuator: 0",
                                                   "position: 0.01, orientation_deg: 0.0057, actuator: 0.005"))
    _poses_csv(tmp_path / "poses.csv")
    run = CliRunner().invoke
    args = ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", str(setup), "--poses",
            str(tmp_path / "poses.csv"), "--sessions", "2", "--session-offsets", "0.5", "--seed", "3"]
    res = run(cli, args + ["-o", str(tmp_path / "m.csv")])
    assert res.exit_code == 0, res.output
    assert "session 2" in res.output and "dq:" in res.output
    again = run(cli, args + ["-o", str(tmp_path / "m2.csv")])
    assert (tmp_path / "m.csv").read_bytes() == (tmp_path / "m2.csv").read_bytes()   # same seed, same bytes
    import pandas

    df = pandas.read_csv(tmp_path / "m.csv")
    assert list(df.columns)[-1] == "session" and sorted(set(df["session"])) == [1, 2]
    res = run(cli, ["identify", "stewart-prototype", str(tmp_path / "m.csv"), "--setup", str(fit_setup),
                    "-o", str(tmp_path / "cal.yaml"), "--json", "--session-offsets"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.output)
    assert d["sessions"]["labels"] == ["1", "2"] and d["sessions"]["actuator_offsets"] is True
    assert set(d["sessions"]["values"]["2"]) == {"world", "tool", "dq"}
    assert d["residual_rms_mm"] < 1e-8
    assert "dq_1@2" in d["parameters"] and d["parameters"]["world.c@2"]["unit"] == "deg"
    # the fit summary names the sessions and their values
    res = run(cli, ["identify", "stewart-prototype", str(tmp_path / "m.csv"), "--setup", str(fit_setup),
                    "-o", str(tmp_path / "cal.yaml"), "--session-offsets"])
    assert "sessions: 2 (1:" in res.output and "session 2 (mm, deg): world:" in res.output


def test_simulate_session_options_need_sessions(tmp_path):
    _poses_csv(tmp_path / "poses.csv")
    res = CliRunner().invoke(cli, ["simulate", "stewart-prototype", "--random-errors", "0.5", "--setup",
                                   "full-pose-paper1", "--poses", str(tmp_path / "poses.csv"), "--session-offsets",
                                   "0.5", "-o", str(tmp_path / "m.csv")])
    assert res.exit_code == 2 and "--sessions" in res.output and not (tmp_path / "m.csv").exists()


def test_session_sensor_bound_to_its_poses(nominal):
    ss = SessionSensor.start(FullPoseSensor(), Sessions.from_labels(["1", "2", "2"]))
    with pytest.raises(PkmcalError, match="bound to 3 poses; got 2"):
        ss.predict(nominal.frame(random_poses(nominal, 2)))
    with pytest.raises(PkmcalError, match="session labels for"):
        Model(nominal, ss, NOISE_FULL, np.zeros((2, 6)), np.zeros((2, 6)), sessions=Sessions.from_labels(["1", "2", "2"]))
    assert replace(ss).session("2") == FullPoseSensor()


def test_prior_without_label_applies_to_every_session(nominal, real):
    q, y, cmd, labels = two_sessions(nominal, real, true_sensors("full-pose"))
    e_y, e_q = NOISE_FULL.sample(np.random.default_rng(4), y.shape, q.shape)
    res = identify(nominal, start_setup("full-pose"), q=q + e_q, y=y + e_y, commanded=cmd, sessions=labels,
                   priors=["tool.z=30±0.01"])
    assert {e["parameter"] for e in res.priors.to_dict(res.estimate, {})} == {"tool.z@A", "tool.z@B"}


def test_identify_report_with_sessions_and_offsets(tmp_path):
    """The HTML report takes a fit with sessions and offsets (their units from the result)."""
    setup = tmp_path / "setup.yaml"
    setup.write_text("sensor: full-pose\ntool: {z: 30}\nfree: [world.x, world.y, world.z, world.a, world.b, world.c]\n"
                     "noise: {position: 0.01, orientation_deg: 0.0057, actuator: 0.005}\n"
                     "sessions: {actuator_offsets: true}\n")
    _poses_csv(tmp_path / "poses.csv")
    run = CliRunner().invoke
    res = run(cli, ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", str(setup),
                    "--poses", str(tmp_path / "poses.csv"), "--sessions", "2", "--session-offsets", "0.3",
                    "-o", str(tmp_path / "m.csv")])
    assert res.exit_code == 0, res.output
    res = run(cli, ["identify", "stewart-prototype", str(tmp_path / "m.csv"), "--setup", str(setup),
                    "-o", str(tmp_path / "cal.yaml"), "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    html = (tmp_path / "rep" / "report.html").read_text()
    assert "dq_1@2" in html and "world.x@2" in html


#: Session labels as instruments and people write them: text without line breaks, not
#: empty, no surrounding spaces (stripped on reading), commas, quotes and '#' allowed.
LABELS = st.text(st.characters(blacklist_categories=("Cc", "Cs", "Zl", "Zp")), min_size=1, max_size=12).map(
    str.strip).filter(lambda t: t != "")


@fuzz_settings(25)
@given(per_pose=st.lists(st.sampled_from(["1", "2", "x, y", '"q"', "2026-05-01-am"]) | LABELS, min_size=1,
                         max_size=12))
def test_session_labels_round_trip_any_text(nominal, tmp_path, per_pose):
    """Any labels: written, read back exactly, in order of first appearance; the groups
    partition the poses."""
    setup = start_setup("full-pose")
    n = len(per_pose)
    x = random_poses(nominal, n, 1)
    meas = Measurements(nominal.ik(x), setup.sensor.predict(nominal.frame(x)), sessions=per_pose)
    path = tmp_path / "m.csv"
    save_measurements(path, meas, nominal, setup)
    back = load_measurements(path, nominal, setup)
    assert [back.sessions.labels[k] for k in back.sessions.index] == per_pose
    assert back.sessions.labels == tuple(dict.fromkeys(per_pose))
    covered = np.concatenate([np.arange(n)[g] for g in back.sessions.groups])
    assert sorted(covered) == list(range(n))
    with open(path, newline="", encoding="utf-8") as fh:
        assert [r["session"] for r in csv.DictReader(fh)] == per_pose


@pytest.mark.parametrize("kind,method", CASES)
def test_far_apart_session_frames_converge(nominal, real, kind, method):
    """A second session whose world frame is 500 mm and 86° from the first and from the
    start: the registration of each session (machine held, through FK) brings the joint
    fit to the noise-free solution (without it the projection's pose solve fails at the
    start and a position-sensor fit stops in a local minimum)."""
    far = [500.0, -300.0, 100.0, 0.3, -0.2, 1.5]
    sensors = ((FullPoseSensor(world=WORLDS[0], tool=TOOL), FullPoseSensor(world=far, tool=TOOL)) if kind == "full-pose"
               else (PositionSensor(target=TARGET, world=WORLDS[0]), PositionSensor(target=TARGET, world=far)))
    q, y, cmd, labels = two_sessions(nominal, real, sensors)
    res = identify(nominal, start_setup(kind), q=q, y=y, commanded=cmd, method=method, sessions=labels)
    assert res.success and res.rms_residual < 1e-9
    assert any("registered on its poses" in w for w in res.warnings)


def test_rotary_delta_offsets_in_degrees():
    """A rotary delta (angle actuators) measured by a tracker in two sessions, re-homed
    between them: the offsets dq_i@2 are angles, recovered (1e-12 rad) and reported in
    degrees (JSON unit, session values)."""
    from pkmcal.identification.simulation import perturb_machine
    from pkmcal.mechanisms import builtin_machine

    nominal = builtin_machine("delta-picker")
    assert all(nominal.actuator_is_angle)
    real = perturb_machine(nominal, 0.3, 1)
    cmd = nominal.home_pose + np.random.default_rng(0).uniform(-1, 1, (60, 3)) * np.array([60.0, 60.0, 30.0])
    q = nominal.ik(cmd)
    dq = np.deg2rad([0.2, -0.3, 0.1])
    moved = q.copy()
    moved[30:] += dq
    fk = real.fk(moved, guess=cmd)
    assert fk.all_converged
    frames = real.frame(fk.poses)
    s1, s2 = PositionSensor(world=[5.0, -3.0, 2.0, 0.01, 0.02, 0.03]), PositionSensor(world=[-40.0, 10.0, 5.0, -0.02,
                                                                                              0.01, 0.4])
    y = np.vstack([s1.predict(frames[:30]), s2.predict(frames[30:])])
    setup = MeasurementSetup(PositionSensor(free=WORLD), NoiseModel(np.full(3, 0.01), np.array(1e-5)))
    res = identify(nominal, setup, q=q, y=y, commanded=cmd, sessions=["1"] * 30 + ["2"] * 30, session_offsets=True)
    assert res.rms_residual < 1e-9
    np.testing.assert_allclose(res.estimate[-3:], dq, rtol=0, atol=1e-12)
    assert res.to_dict()["parameters"]["dq_1@2"]["unit"] == "deg"
    np.testing.assert_allclose(res.session_values()["2"]["dq"], [0.2, -0.3, 0.1], atol=1e-9)
