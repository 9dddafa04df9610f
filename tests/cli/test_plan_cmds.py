"""``pkmcal plan`` output in file units: poses and actuator commands (rotary ones in degrees)
checked against the machine's own inverse kinematics of the written poses."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.tables import read_table
from pkmcal.mechanisms import builtin_machine


@pytest.mark.parametrize("name", ["planar-2dof-3act", "planar-3dof-4act"])
def test_plan_writes_poses_and_commands_in_file_units(name, tmp_path):
    mech = builtin_machine(name)
    out = tmp_path / "poses.csv"
    res = CliRunner().invoke(cli, ["plan", name, "--setup", "planar-tracker", "--n-poses", "6", "--n-candidates", "80",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text().startswith(",".join(mech.pose_names + mech.actuator_names) + "\n")  # plain CSV
    cols = mech.pose_names + mech.actuator_names
    t = read_table(out, cols, kinds={})          # the numbers as written, no unit conversion
    pose_deg = t[list(mech.pose_names)]
    ang = np.array(mech.pose_is_angle)
    poses = pose_deg.copy()
    poses[:, ang] = pose_deg[:, ang] * np.pi / 180.0
    q = mech.ik(poses)
    rotary = np.array(mech.actuator_is_angle)
    q[:, rotary] *= 180.0 / np.pi
    np.testing.assert_allclose(t[list(mech.actuator_names)], q, rtol=1e-12, atol=1e-9)
    assert rotary.any() == (name == "planar-2dof-3act")


def _written_poses(path):
    names = ["x", "y", "z", "a", "b", "c"]
    return read_table(path, names, kinds={})[names]


def test_candidate_angles_beyond_180_are_planned_and_written_wrapped(tmp_path):
    """A candidate file with angles beyond ±180° (the same orientations, whole turns away):
    the plan writes each chosen pose with its angles in (-180, 180], the same rotation as the
    candidate's (scipy), and a note counts them."""
    from helpers import random_poses
    from scipy.spatial.transform import Rotation

    from pkmcal.planning.margins import default_margin, planning_machine

    mech = builtin_machine("stewart-prototype")
    poses = random_poses(mech, 200, seed=4)
    safe = planning_machine(mech, default_margin(mech))            # inside the plan's default margins
    poses = poses[safe.check_limits(poses).ok][:40]
    assert len(poses) == 40
    deg = poses.copy()
    deg[:, 3:] = np.rad2deg(poses[:, 3:])
    turned = deg.copy()
    turned[:30:2, 3] += 360.0                             # 15 rows
    turned[1:30:4, 5] -= 720.0                            # 8 rows
    turned[3:30:4, 4] += 1080.0                           # 7 rows; the last 10 as they were
    cand = tmp_path / "cand.csv"
    cand.write_text("x,y,z,a,b,c\n" + "".join(",".join(repr(float(v)) for v in row) + "\n" for row in turned))
    out = tmp_path / "p.csv"
    res = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "12",
                                   "--candidates", str(cand), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "30 of the 40 candidate poses have angles beyond ±180 deg" in res.output
    got = _written_poses(out)
    assert np.all(got[:, 3:] > -180.0) and np.all(got[:, 3:] <= 180.0)
    rows = [int(np.flatnonzero(np.all(turned[:, :3] == g[:3], axis=1))[0]) for g in got]   # positions unchanged
    same = Rotation.from_euler("xyz", got[:, 3:], degrees=True).inv() * Rotation.from_euler("xyz", turned[rows, 3:],
                                                                                            degrees=True)
    assert np.all(same.magnitude() < 1e-9)
    assert np.any(turned[rows, 3:] != got[:, 3:])       # the test chose some turned poses


def test_declared_workspace_beyond_the_euler_range_is_clipped_with_a_note(tmp_path):
    """A machine file whose workspace box reaches beyond a, c ±180° and b ±90° plans in the
    box clipped to that range, with a note naming the coordinates."""
    from helpers import PROTOTYPE_LEGS_YAML

    machine = tmp_path / "m.yaml"
    machine.write_text("kind: hexapod\nname: wide\nlegs:\n" + PROTOTYPE_LEGS_YAML
                       + "limits: {u_joint_tilt: 45, s_joint_tilt: 29}\n"
                       + "home: {x: 0, y: 0, z: 315, a: 0, b: 0, c: 0}\n"
                       + "workspace: {x: [-20, 20], y: [-20, 20], z: [300, 330], a: [-400, 400], b: [-100, 30], "
                       + "c: [-10, 10]}\n")
    out = tmp_path / "p.csv"
    res = CliRunner().invoke(cli, ["plan", str(machine), "--setup", "full-pose-paper1", "--n-poses", "8",
                                   "--n-candidates", "100", "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "workspace box ('workspace:' in the machine file) is clipped: a [-400, 400] deg -> [-180, 180], " \
           "b [-100, 30] deg -> [-90, 30]" in res.output
    got = _written_poses(out)
    assert np.all(np.abs(got[:, 3]) <= 180.0) and np.all(got[:, 4] >= -90.0)
    # and the rotations of that box are mostly beyond the prototype's joints (0.35 % of it
    # passes): planning draws in the reach from home instead, and says so
    assert "workspace box ('workspace:' in the machine file) is mostly beyond what the machine reaches" in res.output
    assert np.all(np.abs(got[:, 3:5]) < 15.0)


@pytest.mark.parametrize("args", [
    ["stewart-prototype", "--setup", "indicators-prototype", "--n-poses", "15", "--n-candidates", "300", "--seed", "1"],
    ["kossel-mini", "--setup", "z-probe-klipper", "--n-poses", "20", "--target-accuracy", "0.003"],
])
def test_plan_json_is_the_printed_summary(args, tmp_path):
    """``plan --json`` carries what the text summary prints (the text is made from the same
    dict); its counts add up, its indices are the written poses' (pkmcal observability); the
    same plan either way (same seed, same bytes); -o - with --json is refused."""
    import json

    from pkmcal.cli.plan_cmds import plan_summary_lines

    text = CliRunner().invoke(cli, ["plan", *args, "-o", str(tmp_path / "a.csv")])
    js = CliRunner().invoke(cli, ["plan", *args, "-o", str(tmp_path / "b.csv"), "--json"])
    assert text.exit_code == js.exit_code == 0, js.output
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()
    data = json.loads(js.stdout)
    assert plan_summary_lines(data) + [f"wrote {tmp_path / 'a.csv'}"] == text.stdout.splitlines()
    cand = data["candidates"]
    assert cand["accepted"] <= cand["tested"] and data["output"] == str(tmp_path / "b.csv")
    assert data["selection"]["n_poses"] == int(args[args.index("--n-poses") + 1])
    obs = CliRunner().invoke(cli, ["observability", args[0], "--setup", args[2], "--poses", str(tmp_path / "a.csv"),
                                   "--json"])
    assert obs.exit_code == 0, obs.output
    observed = json.loads(obs.stdout)
    for k, v in data["indices"].items():
        # the same function of the same poses (the CSV holds them in degrees to repr precision: round-off)
        assert v == pytest.approx(observed[k], rel=1e-9), k
    res = CliRunner().invoke(cli, ["plan", *args, "--json"])
    assert res.exit_code == 2 and "-o FILE" in res.stderr
