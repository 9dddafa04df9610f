"""Candidate poses: workspace box, corners, generators, CSV input, limit and measurability checks."""

import numpy as np
import pytest

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.candidates import (
    Measurability,
    check_candidates,
    corner_box,
    corner_poses,
    generate_candidates,
    grid_poses,
    measurability_violations,
    read_candidates_csv,
    workspace_box,
)
from pkmcal.sensors import FullPoseSensor, MeasurementSetup, NoiseModel


@pytest.fixture(scope="module")
def machine():
    return stewart_prototype()


@pytest.fixture(scope="module")
def indicators():
    return load_setup("indicators-prototype")


@pytest.fixture(scope="module")
def box(machine, indicators):
    return workspace_box(machine, indicators)


def test_corner_poses_are_the_64_corners():
    box = np.array([[-1, 1], [-2, 2], [10, 20], [-0.1, 0.1], [-0.2, 0.2], [0, 0.5]], dtype=float)
    c = corner_poses(box)
    assert c.shape == (64, 6) and len(np.unique(c, axis=0)) == 64
    assert np.all((c == box[:, 0]) | (c == box[:, 1]))


def test_workspace_box_is_the_per_axis_reach(machine, indicators, box):
    home = machine.home
    assert np.allclose(box.mean(axis=1), home)
    for k in range(6):
        ends = np.tile(home, (2, 1))
        ends[:, k] = box[k]
        assert check_candidates(machine, indicators, ends, margin=0.1).ok.all()
        half = box[k, 1] - home[k]
        if half < 0.99 * np.array([50, 50, 25, 50 / 70, 50 / 70, 50 / 70])[k]:   # limited, not the shape cap
            beyond = np.tile(home, (2, 1))
            beyond[:, k] = [home[k] - 1.01 * half, home[k] + 1.01 * half]
            assert not check_candidates(machine, indicators, beyond, margin=0.1).ok.all()


def test_corner_box_is_the_largest_all_reachable_scaled_box(machine, indicators, box):
    cb = corner_box(machine, box, indicators, margin=0.1)
    assert check_candidates(machine, indicators, corner_poses(cb), margin=0.1).ok.all()
    c, h = cb.mean(axis=1), (cb[:, 1] - cb[:, 0]) / 2
    bigger = np.stack([c - 1.01 * h, c + 1.01 * h], axis=1)
    assert not check_candidates(machine, indicators, corner_poses(bigger), margin=0.1).ok.all()


def test_random_candidates_pass_checks_and_rejections_add_up(machine, indicators, box):
    cs = generate_candidates(machine, indicators, n=300, rng=np.random.default_rng(0), box=box)
    assert cs.poses.shape == (300, 6)
    assert check_candidates(machine, indicators, cs.poses).ok.all()
    assert np.all((cs.poses >= box[:, 0]) & (cs.poses <= box[:, 1]))
    n_rejected = cs.n_tested - 300
    assert n_rejected > 0
    assert max(cs.rejected.values()) <= n_rejected <= sum(cs.rejected.values())
    again = generate_candidates(machine, indicators, n=300, rng=np.random.default_rng(0), box=box)
    assert np.array_equal(cs.poses, again.poses)


def test_grid_and_corner_kinds(machine, indicators, box):
    g = grid_poses(box, 3)
    assert g.shape == (729, 6)
    cs = generate_candidates(machine, indicators, kind="corners", box=box)
    assert cs.poses.shape == (64, 6) and cs.rejected == {}
    with pytest.raises(PkmcalError, match="at least 2 points"):
        grid_poses(box, 1)


def test_indicator_measurability(machine, indicators):
    home = machine.home[None]
    z = indicators.sensor.predict(home)[0]
    ok = measurability_violations(indicators, home, Measurability(travel=(z.min() - 1, z.max() + 1)))
    assert not any(v.any() for v in ok.values())
    bad = measurability_violations(indicators, home, Measurability(travel=(z.max() + 1, z.max() + 10)))
    assert bad["indicator_travel"].all()
    # indicators at radius 40 mm: a 30 mm plate misses them, a 50 mm plate does not
    assert measurability_violations(indicators, home, Measurability(plate_radius=30.0))["indicator_off_plate"].all()
    assert not measurability_violations(indicators, home, Measurability(plate_radius=50.0))["indicator_off_plate"].any()
    flipped = machine.home + np.array([0, 0, 0, np.pi * 0.75, 0, 0])
    assert measurability_violations(indicators, flipped[None])["indicator_plane_tilt"].all()


def test_line_of_sight_cone(machine):
    # sensor 1000 mm above the base origin: the base sits at z = -1000 in the sensor frame
    setup = MeasurementSetup(FullPoseSensor(world=np.array([0, 0, -1000.0, 0, 0, 0])),
                             NoiseModel(np.full(6, 0.01), np.array(0.01)))
    level = machine.home
    tilted = machine.home + np.array([0, 0, 0, np.deg2rad(20), 0, 0])
    v = measurability_violations(setup, np.array([level, tilted]), Measurability(sight_cone=np.deg2rad(10)))
    assert v["line_of_sight"].tolist() == [False, True]


def test_read_candidates_csv(tmp_path):
    p = tmp_path / "c.csv"
    p.write_text("x,y,z,a,b,c\n1,2,300,10,0,-5\n")
    poses = read_candidates_csv(p)
    assert np.allclose(poses, [[1, 2, 300, np.deg2rad(10), 0, np.deg2rad(-5)]])
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y,z,a,b\n1,2,3,4,5\n")
    with pytest.raises(InputFileError, match="bad.csv"):
        read_candidates_csv(bad)


def test_read_candidates_csv_planar_converts_the_declared_angle_columns(tmp_path):
    """A planar machine's pose file: x, y (mm) kept, φ (its ``pose_is_angle``) read in degrees."""
    from pkmcal.mechanisms import planar as PL

    m3, m2 = PL.planar_3dof_4act(), PL.planar_2dof_3act()
    p = tmp_path / "p3.csv"
    p.write_text("x,y,phi\n10,220,12.5\n-3,200,-7\n")
    np.testing.assert_array_equal(read_candidates_csv(p, m3),
                                  [[10.0, 220.0, np.deg2rad(12.5)], [-3.0, 200.0, np.deg2rad(-7.0)]])
    q = tmp_path / "p2.csv"
    q.write_text("y,x\n220,10\n")
    np.testing.assert_array_equal(read_candidates_csv(q, m2), [[10.0, 220.0]])
