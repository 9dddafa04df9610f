"""Verification on held-out poses: zero error for the exact model, errors against
independent constructions, summaries, dropped poses, JSON and table output."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pkmcal.errors import PkmcalError
from pkmcal.identification.verification import pose_errors, pose_errors_many, verify
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real

NOMINAL = stewart_prototype()
REAL = stewart_prototype_real()


def _poses(n, seed=0):
    rng = np.random.default_rng(seed)
    p = np.tile(NOMINAL.home, (n, 1))
    p[:, :3] += rng.uniform(-15, 15, (n, 3))
    p[:, 3:] += rng.uniform(-0.08, 0.08, (n, 3))
    return p


def test_exact_model_has_zero_error():
    e = pose_errors(REAL, REAL, _poses(30))
    assert e.valid.all()
    assert np.max(e.position) < 1e-9 and np.max(e.orientation) < 1e-11
    assert np.max(e.tilt) < 1e-11 and np.max(np.abs(e.height)) < 1e-9


def test_errors_match_independent_construction():
    poses = _poses(25)
    e = pose_errors(NOMINAL, REAL, poses)
    assert e.valid.all()
    # the reached pose is where the real machine's legs have the commanded lengths
    np.testing.assert_allclose(REAL.ik(e.reached), NOMINAL.ik(poses), atol=1e-8)
    rc = Rotation.from_euler("xyz", poses[:, 3:])
    rr = Rotation.from_euler("xyz", e.reached[:, 3:])
    np.testing.assert_allclose(e.orientation, (rr * rc.inv()).magnitude(), rtol=1e-9, atol=1e-13)
    np.testing.assert_allclose(e.position, np.sqrt(((e.reached[:, :3] - poses[:, :3]) ** 2).sum(1)), rtol=1e-12)
    nc, nr = rc.apply([0, 0, 1]), rr.apply([0, 0, 1])
    np.testing.assert_allclose(e.tilt, np.arccos(np.clip((nc * nr).sum(1), -1, 1)), rtol=1e-6, atol=1e-9)
    # height: plane through three points of the real platform plane, hit by the vertical
    # line through the commanded centre
    for k in range(len(poses)):
        pts = e.reached[k, :3] + rr[k].apply([[0, 0, 0], [50, 0, 0], [0, 50, 0]])
        u, v = pts[1] - pts[0], pts[2] - pts[0]
        s, t = np.linalg.solve([[u[0], v[0]], [u[1], v[1]]], poses[k, :2] - pts[0, :2])
        np.testing.assert_allclose(e.height[k], pts[0, 2] + s * u[2] + t * v[2] - poses[k, 2], atol=1e-9)
    # paper 2's Table 4 deviations move the platform by millimetres and about a degree
    assert 1.0 < np.mean(e.position) < 20.0 and 0.002 < np.mean(e.orientation) < 0.1


def test_report_summaries_and_outputs():
    poses = _poses(20, seed=3)
    poses[4, 2] += 300.0                       # unreachable: beyond the stroke
    rep = verify(REAL, REAL, poses, nominal=NOMINAL)
    d = rep.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["poses"] == 20 and d["used"] == 19
    assert d["dropped"] == [{"pose": 5, "reason": rep.dropped[4]}]
    mask = rep.common
    before = rep.before.position[mask]
    assert d["before"]["position_mean_mm"] == pytest.approx(before.mean())
    assert d["before"]["position_max_mm"] == pytest.approx(before.max())
    assert d["before"]["position_rms_mm"] == pytest.approx(np.sqrt((before**2).mean()))
    assert d["before"]["height_max_mm"] == pytest.approx(np.abs(rep.before.height[mask]).max())
    assert d["after"]["position_max_mm"] < 1e-9
    assert d["reduction_percent"]["position_mean"] == pytest.approx(100.0, abs=1e-6)
    table = rep.format_table()
    assert "verification on 19 of 20 held-out poses" in table
    assert "pose 5 not used" in table and "before" in table and "after" in table
    # without a nominal model: no "before"
    only = verify(REAL, REAL, _poses(5)).to_dict()
    assert "before" not in only and "after" in only


def test_many_models_at_once_give_each_model_its_own_numbers():
    """pose_errors_many does one FK and one limit check for K models: each result must hold
    exactly (bit for bit) what its own pose_errors call gives, dropped poses included."""
    poses = _poses(12, seed=5)
    poses[3, 2] += 300.0                       # beyond the stroke: IK NaN or real limits
    poses[7, 3] += 0.6                         # a tilt the real machine's joints refuse
    third = NOMINAL.with_params(NOMINAL.params + np.r_[np.random.default_rng(1).uniform(-0.2, 0.2, 42), np.zeros(6)], name="third")
    models = (NOMINAL, REAL, third)
    together = pose_errors_many(models, REAL, poses, ("leg_collision",))
    assert len(together) == 3
    for model, got in zip(models, together):
        alone = pose_errors(model, REAL, poses, ("leg_collision",))
        assert got.model == alone.model and got.dropped == alone.dropped
        assert got.dropped, "the test poses must drop some poses"
        for field in ("reached", "position", "orientation", "tilt", "height", "valid"):
            np.testing.assert_array_equal(getattr(got, field), getattr(alone, field), err_msg=field)
    # and verify's before/after (computed together) are those of separate calls
    rep = verify(third, REAL, poses, nominal=NOMINAL, ignore_limits=("leg_collision",))
    np.testing.assert_array_equal(rep.after.position, together[2].position)
    np.testing.assert_array_equal(rep.before.position, together[0].position)


def test_no_reachable_pose_is_an_error():
    poses = _poses(3)
    poses[:, 2] += 500.0
    with pytest.raises(PkmcalError, match="reaches none of the 3 held-out poses"):
        verify(REAL, REAL, poses, nominal=NOMINAL)


def test_cli_verify_table_and_json(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli
    from pkmcal.conventions import poses_to_file_units

    pf = tmp_path / "held.csv"
    pf.write_text("x,y,z,a,b,c\n" + "".join(",".join(repr(float(v)) for v in r) + "\n"
                                            for r in poses_to_file_units(_poses(6, seed=8))))
    base = ["verify", "stewart-prototype-real", "--real", "stewart-prototype-real", "--poses", str(pf),
            "--nominal", "stewart-prototype"]
    r = CliRunner().invoke(cli, base + ["--json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    for side in ("before", "after"):
        assert {"position_mean_mm", "position_max_mm", "position_rms_mm", "orientation_mean_rad",
                "orientation_max_rad", "orientation_rms_rad", "tilt_mean_rad", "height_rms_mm"} <= set(d[side])
    assert d["after"]["position_max_mm"] < 1e-9 < d["before"]["position_mean_mm"]
    r = CliRunner().invoke(cli, base)
    assert r.exit_code == 0 and "position error mean (mm)" in r.output
    r = CliRunner().invoke(cli, ["verify", "nope-machine", "--real", "stewart-prototype-real", "--poses", str(pf)])
    assert r.exit_code == 2 and "unknown machine 'nope-machine'" in r.output


def test_redundant_tool_error_summary_against_numpy():
    """Planar held-out summaries: tool in mm, |angle| in degrees, NaN angles (n = 2) omitted."""
    from pkmcal.identification.tool_errors import ToolErrors

    rng = np.random.default_rng(4)
    tool, angle = rng.uniform(0.0, 1.0, 6), rng.normal(0.0, 1e-3, 6)
    mask = np.array([True, True, False, True, True, False])
    s = ToolErrors("m", tool, angle, np.ones(6, bool)).summary(mask)
    a = np.rad2deg(np.abs(angle[mask]))
    assert s["poses"] == 4
    assert s["tool_mean_mm"] == pytest.approx(tool[mask].mean()) and s["tool_max_mm"] == pytest.approx(tool[mask].max())
    assert s["tool_rms_mm"] == pytest.approx(np.sqrt(np.mean(tool[mask] ** 2)))
    assert s["angle_max_deg"] == pytest.approx(a.max()) and s["angle_rms_deg"] == pytest.approx(np.sqrt(np.mean(a**2)))
    two = ToolErrors("m", tool, np.full(6, np.nan), np.ones(6, bool)).summary(mask)
    assert not any(k.startswith("angle") for k in two)
