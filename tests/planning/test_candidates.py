"""Candidate poses: workspace box, corners, generators, CSV input, limit and measurability
checks; chunked generation against the one-batch loop it replaces (same poses, counts and
random state whatever the chunk size) and plans that do not depend on the chunk size."""

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
from pkmcal.planning.indices import observability_indices
from pkmcal.planning.blocks import planning_model, raw_blocks
from pkmcal.planning.plan import candidate_blocks, plan_poses
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
    z = indicators.sensor.predict(machine.frame(home))[0]
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


# -- chunked generation: same candidates whatever the chunk size, exact rejection counts ------


def _unchunked_random(machine, setup, n, rng, box, margin=0.1, measurability=Measurability()):
    """The one-batch-per-round loop that the chunked generator replaces, spelled out: rounds
    of max(4·(n − accepted), 256) poses, each checked as a whole, counted up to the pose
    that completes n."""
    kept, tested, rejected, total = [], 0, {}, 0
    while total < n:
        batch = box[:, 0] + rng.random((max(4 * (n - total), 256), 6)) * (box[:, 1] - box[:, 0])
        chk = check_candidates(machine, setup, batch, margin=margin, measurability=measurability)
        ok = chk.ok
        used = len(batch) if ok.sum() < n - total else int(np.flatnonzero(ok)[n - total - 1]) + 1
        tested += used
        for k, v in chk.violations.items():
            rejected[k] = rejected.get(k, 0) + int(v[:used].sum())
        kept.append(batch[:used][ok[:used]])
        total += len(kept[-1])
    return np.concatenate(kept), tested, {k: v for k, v in rejected.items() if v}


@pytest.mark.parametrize("chunk_size", [7, 97, 1000, 10**6])
def test_random_candidates_do_not_depend_on_the_chunk_size(machine, indicators, box, chunk_size):
    spec = Measurability(travel=(285.0, 330.0), plate_radius=80.0)      # every reason occurs
    rng = np.random.default_rng(11)
    poses, tested, rejected = _unchunked_random(machine, indicators, 700, rng, box, measurability=spec)
    rng2 = np.random.default_rng(11)
    cs = generate_candidates(machine, indicators, n=700, rng=rng2, box=box, measurability=spec,
                             chunk_size=chunk_size)
    np.testing.assert_array_equal(cs.poses, poses)
    assert cs.n_tested == tested and cs.rejected == rejected
    assert {"stroke", "s_joint_tilt", "leg_collision", "indicator_travel", "indicator_off_plate"} <= set(rejected)
    assert rng2.random() == rng.random()     # the generator ends in the same state


def test_rejection_counts_are_those_of_checking_the_tested_poses(machine, indicators, box):
    # fixed sets (grid, file): counts = check_candidates over all poses, for any chunk size
    grid = grid_poses(box, 4)
    whole = check_candidates(machine, indicators, grid)
    for chunk_size in (1, 333, 4096, 5000):
        cs = generate_candidates(machine, indicators, kind="grid", grid_per_axis=4, box=box, chunk_size=chunk_size)
        assert cs.n_tested == len(grid) and cs.rejected == whole.counts()
        np.testing.assert_array_equal(cs.poses, grid[whole.ok])
        f = generate_candidates(machine, indicators, kind="file", poses=grid[::-1], chunk_size=chunk_size)
        assert f.rejected == whole.counts() and f.kind == "file"
        np.testing.assert_array_equal(f.poses, grid[::-1][whole.ok[::-1]])


def test_only_accepted_candidates_get_blocks(machine, indicators):
    calls = []

    def recording_map(fn, items):          # an in-order executor that records what it runs
        items = list(items)
        calls.append((getattr(fn, "__name__", getattr(getattr(fn, "func", None), "__name__", "")), items))
        return map(fn, items)

    plan = plan_poses(machine, indicators, 20, n_candidates=900, seed=2, chunk_size=700, chunk_map=recording_map)
    blocked = [np.concatenate(items) for name, items in calls if name == "blocks"]
    assert len(blocked) == 1
    np.testing.assert_array_equal(blocked[0], plan.candidates.poses)     # the 900 accepted, nothing else
    assert check_candidates(machine, indicators, blocked[0]).ok.all()
    assert sum(len(items) for name, items in calls if name == "check_chunk") > 1   # checked in chunks


def test_an_eager_executor_map_gives_the_same_candidates(machine, indicators, box):
    from concurrent.futures import ThreadPoolExecutor

    ref = generate_candidates(machine, indicators, n=900, rng=np.random.default_rng(4), box=box, chunk_size=500)
    with ThreadPoolExecutor(2) as pool:
        cs = generate_candidates(machine, indicators, n=900, rng=np.random.default_rng(4), box=box, chunk_size=500,
                                 chunk_map=pool.map)
    np.testing.assert_array_equal(cs.poses, ref.poses)
    assert (cs.n_tested, cs.rejected) == (ref.n_tested, ref.rejected)


def test_progress_is_reported_per_chunk(machine, indicators, box):
    calls = []
    generate_candidates(machine, indicators, n=400, rng=np.random.default_rng(0), box=box, chunk_size=300,
                        progress=lambda done, total: calls.append((done, total)))
    done = [d for d, _ in calls]
    assert len(calls) > 3 and all(t == 400 for _, t in calls)
    assert done == sorted(done) and done[-1] == 400
    calls.clear()
    generate_candidates(machine, indicators, kind="grid", grid_per_axis=3, box=box, chunk_size=100,
                        progress=lambda done, total: calls.append((done, total)))
    assert calls == [(min(100 * (i + 1), 729), 729) for i in range(8)]


def test_chunk_size_must_be_positive(machine, indicators, box):
    with pytest.raises(PkmcalError, match="chunk_size"):
        generate_candidates(machine, indicators, n=10, box=box, chunk_size=0)


@pytest.mark.parametrize("kw", [dict(algorithm="default"), dict(algorithm="cuckoo"), dict(algorithm="random"),
                                dict(grid=4), dict(algorithm="corners")])
def test_plans_do_not_depend_on_the_chunk_size(machine, indicators, kw):
    n_cand = {} if "grid" in kw or kw.get("algorithm") == "corners" else dict(n_candidates=1200)
    ref = plan_poses(machine, indicators, 20, seed=6, chunk_size=10**6, **n_cand, **kw)
    for chunk_size in (50, 999):
        p = plan_poses(machine, indicators, 20, seed=6, chunk_size=chunk_size, **n_cand, **kw)
        np.testing.assert_array_equal(p.poses, ref.poses)
        np.testing.assert_array_equal(p.candidates.poses, ref.candidates.poses)
        assert p.candidates.rejected == ref.candidates.rejected and p.selection.indices == ref.selection.indices
    assert observability_indices(ref.model.blocks(ref.candidates.poses)[0], ref.selection.chosen) == \
        ref.selection.indices


def test_blocks_in_batches_are_those_computed_at_once(machine, indicators):
    plan = plan_poses(machine, indicators, 20, n_candidates=1500, seed=1)
    G_all, ok_all = plan.model.blocks(plan.candidates.poses)
    for batch in (300, 701, 1500, 10**6):      # batches of ≥ batch/2 poses: 150 .. 1500
        G, ok = candidate_blocks(plan.model, plan.candidates.poses, batch=batch)
        np.testing.assert_array_equal(G, G_all)
        np.testing.assert_array_equal(ok, ok_all)


@pytest.mark.parametrize("setup_name", ["full-pose-paper1", "laser-tracker", "indicators-prototype"])
def test_blocks_of_the_identifiable_columns_are_those_columns_of_all(machine, setup_name):
    """raw_blocks(columns=...) (sensor columns skipped when none is asked for) gives the same
    numbers as those columns of all P columns: whitening mixes rows only."""
    setup = load_setup(setup_name)
    model = planning_model(machine, setup)
    poses = generate_candidates(machine, setup, kind="random", n=300, rng=np.random.default_rng(4)).poses
    J_all, ok_all, names = raw_blocks(machine, setup, poses, model.method)
    J, ok, _ = raw_blocks(machine, setup, poses, model.method, columns=model.free_index)
    np.testing.assert_array_equal(J, J_all[:, :, model.free_index])
    np.testing.assert_array_equal(ok, ok_all)
    assert np.isfinite(J).all()
    sensor_free = [names[i] for i in model.free_index if i >= len(machine.param_names)]
    assert bool(sensor_free) == (setup_name == "laser-tracker")   # the target offset: both paths taken


@pytest.mark.parametrize("n", [1, 15, 63])
def test_small_batches_without_margins_give_the_numpy_verdicts(machine, box, n):
    """Below LIMITS_COMPILED_FROM poses, check_limits(margins=False) (what candidates,
    simulation and verification ask) runs the compiled kernel, check_limits() the NumPy
    formulas: the same verdicts for every limit, also for poses right at a limit (a
    bisection between home and a rejected pose puts each within 1e-9 of its boundary)."""
    rng = np.random.default_rng(n)
    lo, hi = box[:, 0], box[:, 1]
    poses = lo + rng.uniform(size=(4 * n, 6)) * (hi - lo) * 1.6 - 0.3 * (hi - lo)
    full = machine.check_limits(poses)
    outside = np.flatnonzero(~full.ok)
    edge = []
    for k in outside[:n]:
        a, b = 0.0, 1.0                                   # home + t (pose - home): ok at 0, not at 1
        for _ in range(40):
            t = 0.5 * (a + b)
            p = machine.home_pose + t * (poses[k] - machine.home_pose)
            a, b = (t, b) if machine.check_limits(p[None]).ok[0] else (a, t)
        edge += [machine.home_pose + a * (poses[k] - machine.home_pose), machine.home_pose + b * (poses[k] - machine.home_pose)]
    batch = np.vstack([np.array(edge).reshape(-1, 6), poses])[:n]       # both sides of the limits first
    fast, ref = machine.check_limits(batch, margins=False), machine.check_limits(batch)
    assert fast.margins == {} and set(fast.violations) == set(ref.violations)
    for name in ref.violations:
        np.testing.assert_array_equal(fast.violations[name], ref.violations[name], err_msg=name)
    if n > 1:
        assert 0 < ref.ok.sum() < n
