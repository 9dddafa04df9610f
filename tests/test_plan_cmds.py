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
    res = CliRunner().invoke(cli, ["plan", name, "--setup", "planar-tracker", "--n", "6", "--n-candidates", "80",
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
