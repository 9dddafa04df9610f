"""Actuator readings outside the stroke or stuck at its ends are reported per pose and not
silently used (issue 11 item 1c; :func:`pkmcal.io.measurements.clipped_readings`,
``identify --clipped drop|keep|error``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io.measurements import Measurements, apply_clipped_policy, clipped_readings
from pkmcal.mechanisms.library import builtin_machine

MACHINE = builtin_machine("stewart-prototype")          # stroke [0, 50] mm on every leg


def _meas(lam):
    lam = np.array(lam, dtype=float)
    return Measurements(actuators=lam, readings=np.zeros((len(lam), 3)), source="m.csv",
                        lines=np.arange(3, 3 + len(lam)), rows=np.arange(1, 1 + len(lam)))


def test_readings_outside_or_at_the_ends_are_found_with_pose_line_and_stroke():
    lam = np.full((5, 6), 25.0)
    lam[1, 2] = 50.0                  # stuck at the top
    lam[2, 0] = 50.0 + 1e-6           # beyond it
    lam[3, 5] = -0.25                 # below the bottom
    lam[4, 4] = 0.0                   # at the bottom
    lam[0, 1] = 50.0 - 1e-6           # inside: a real reading near the end is not flagged
    found = clipped_readings(_meas(lam), MACHINE)
    assert [(c.pose, c.line, c.actuator, c.kind) for c in found] == [
        (2, 4, "lambda3", "at-end"), (3, 5, "lambda1", "outside"), (4, 6, "lambda6", "outside"),
        (5, 7, "lambda5", "at-end")]
    assert found[2].reading == -0.25 and found[2].stroke == (0.0, 50.0)
    assert found[0].describe() == ("pose 2 (line 4): lambda3 = 50.0 mm is at an end of its stroke (stuck or "
                                   "clipped?) [0.0, 50.0] mm")
    assert clipped_readings(_meas(np.full((3, 6), 25.0)), MACHINE) == []


def test_policies_drop_keep_error_and_pose_numbers_survive_dropping():
    lam = np.full((6, 6), 25.0)
    lam[1, 0] = 50.0
    lam[4, 3] = 60.0
    meas = _meas(lam)
    kept, found, lines = apply_clipped_policy(meas, MACHINE, "drop")
    assert len(found) == 2 and len(kept) == 4
    np.testing.assert_array_equal(kept.pose_numbers, [1, 3, 4, 6])
    np.testing.assert_array_equal(kept.lines, [3, 5, 6, 8])
    assert lines[0] == "m.csv: pose 2 (line 4): lambda1 = 50.0 mm is at an end of its stroke (stuck or clipped?) " \
                       "[0.0, 50.0] mm"
    assert lines[-1].startswith("m.csv: 2 pose(s) with clipped readings left out (--clipped drop, the default")
    assert lines[-1].endswith(": 2, 5")
    # dropping again from the subset keeps the file's numbers
    again = kept.subset([True, False, True, True])
    np.testing.assert_array_equal(again.pose_numbers, [1, 4, 6])
    same, found_keep, lines_keep = apply_clipped_policy(meas, MACHINE, "keep")
    assert same is meas and len(found_keep) == 2 and "used (--clipped keep)" in lines_keep[-1]
    with pytest.raises(PkmcalError, match=r"2 clipped actuator reading\(s\) in 2 pose\(s\): m.csv: pose 2 \(line 4\)"):
        apply_clipped_policy(meas, MACHINE, "error")
    with pytest.raises(PkmcalError, match="every pose has a clipped actuator reading"):
        apply_clipped_policy(_meas(np.full((2, 6), 50.0)), MACHINE, "drop")
    with pytest.raises(PkmcalError, match="--clipped 'ignore'"):
        apply_clipped_policy(meas, MACHINE, "ignore")


def test_a_machine_without_a_stroke_has_nothing_clipped():
    planar = builtin_machine("planar-3dof-4act")
    m = Measurements(actuators=np.full((2, planar.n_actuators), 1e3), readings=np.zeros((2, 2)))
    assert clipped_readings(m, planar) == []


def test_identify_reports_drops_keeps_or_refuses_clipped_poses(tmp_path):
    runner = CliRunner()
    poses, meas = tmp_path / "poses.csv", tmp_path / "meas.csv"
    res = runner.invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "20",
                              "--n-candidates", "300", "--seed", "3", "-o", str(poses)])
    assert res.exit_code == 0, res.output
    res = runner.invoke(cli, ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                              "full-pose-paper1", "--poses", str(poses), "--seed", "4", "-o", str(meas)])
    assert res.exit_code == 0, res.output
    header, *rows = meas.read_text().splitlines()
    names = header.split(",")
    cells = [r.split(",") for r in rows]
    cells[6][names.index("lambda3")] = "50.0"      # pose 7 (line 8): stuck at the top of the stroke
    cells[11][names.index("lambda1")] = "53.5"     # pose 12 (line 13): beyond it
    meas.write_text("\n".join([header] + [",".join(c) for c in cells]) + "\n")
    base = ["identify", "stewart-prototype", str(meas), "--setup", "full-pose-paper1", "--method", "ik-residual"]
    res = runner.invoke(cli, [*base, "-o", str(tmp_path / "cal.yaml"), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert out["n_poses"] == 18
    assert [(c["pose"], c["line"], c["actuator"], c["reading_mm"], c["kind"]) for c in out["clipped"]] == [
        (7, 8, "lambda3", 50.0, "at-end"), (12, 13, "lambda1", 53.5, "outside")]
    assert any("pose 7 (line 8): lambda3 = 50.0 mm is at an end of its stroke" in w for w in out["warnings"])
    res = runner.invoke(cli, [*base, "-o", str(tmp_path / "cal2.yaml")])
    assert res.exit_code == 0, res.output
    text = res.output
    assert "pose 12 (line 13): lambda1 = 53.5 mm is outside its stroke [0.0, 50.0] mm" in text
    assert "2 pose(s) with clipped readings left out (--clipped drop, the default; --clipped keep uses them): 7, 12" \
        in text
    # kept, the clipped readings are wrong by millimetres: the fit is refused (issue 24), they are named
    res = runner.invoke(cli, [*base, "-o", str(tmp_path / "cal3.yaml"), "--clipped", "keep"])
    assert res.exit_code == 2 and "refused" in res.stderr and "are used (--clipped keep): 7, 12" in res.stderr, res.output
    res = runner.invoke(cli, [*base, "-o", str(tmp_path / "cal3.yaml"), "--json", "--clipped", "keep",
                              "--accept-bad-fit"])
    assert res.exit_code == 0 and json.loads(res.stdout)["n_poses"] == 20
    res = runner.invoke(cli, [*base, "-o", str(tmp_path / "cal4.yaml"), "--clipped", "error"])
    assert res.exit_code == 2 and "2 clipped actuator reading(s) in 2 pose(s)" in res.stderr
    assert not (tmp_path / "cal4.yaml").exists()
    # a fit that fails for want of poses says which were left out, on its one error line
    few = tmp_path / "few.csv"
    few.write_text("\n".join([header] + [",".join(c) for c in cells[:7]]) + "\n")
    res = runner.invoke(cli, ["identify", "stewart-prototype", str(few), "--setup", "full-pose-paper1", "--method",
                              "ik-residual", "-o", str(tmp_path / "cal5.yaml")])
    err = res.stderr.strip()
    assert res.exit_code == 2 and "\n" not in err and err.startswith("pkmcal: error: "), res.output
    assert err.endswith("1 pose(s) with clipped readings left out (--clipped drop, the default; --clipped keep uses "
                        "them): 7)"), err
