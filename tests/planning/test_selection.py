"""Pose selection: low-rank updates against direct recomputation, optimality, reproducibility,
and planned poses checked against the machine's limits independently of the planner."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.io.setup_file import load_setup
from pkmcal.io.tables import read_table
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning import _selection_kernels as kernels
from pkmcal.planning.indices import information_matrix, log_det_information, observability_indices
from pkmcal.planning.plan import plan_poses, pose_set_indices
from pkmcal.planning.selection import (
    _detmax_exchange,
    _DState,
    levy_steps,
    select,
    select_cuckoo,
    select_default,
    select_detmax,
    select_random,
)


def blocks(seed=0, N=60, m=2, p=6):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((N, m, p)) * rng.uniform(0.2, 1.0, (N, 1, 1))


@pytest.mark.parametrize("m, p", [(2, 6), (6, 14)])      # m = 6: the full-pose kernel path
def test_rank_updates_of_all_candidates_match_recomputation(m, p):
    G = np.ascontiguousarray(blocks(2, m=m, p=p))
    state = _DState(G, information_matrix(G, np.arange(8)))
    for k, sign in ((30, 1.0), (41, 1.0), (2, -1.0), (30, -1.0), (55, 1.0)):
        state.update(k, sign)
    M = information_matrix(G, [0, 1, 3, 4, 5, 6, 7, 41, 55])
    assert np.allclose(state.M, M)
    Minv = np.linalg.inv(M)
    S = np.einsum("nip,pq,njq->nij", G, Minv, G)
    assert np.allclose(state.S, S, rtol=1e-8, atol=1e-11)
    gains = np.array([np.linalg.slogdet(M + g.T @ g)[1] for g in G]) - np.linalg.slogdet(M)[1]
    assert np.allclose(state.gains(), gains, rtol=1e-8, atol=1e-10)


def test_working_set_size():
    """All N up to max(10,000, 5 × pool); above, 5 × pool capped by the 750,000-number
    budget, never below the pool."""
    from pkmcal.planning.selection import _work_size

    assert _work_size(10_000, 2000, 6, 42) == 10_000 and _work_size(11_000, 2200, 6, 42) == 11_000
    assert _work_size(100_000, 2200, 6, 42) == 750_000 // 252 == 2976     # full pose, 42 parameters
    assert _work_size(100_000, 2000, 3, 39) == 750_000 // 117              # tracker or indicators
    assert _work_size(100_000, 2000, 1, 15) == 10_000                      # Z probe: 5 × pool
    assert _work_size(10**6, 12_000, 6, 42) == 12_000                      # never below the pool


def test_kernel_gain_is_minus_inf_when_not_positive_definite():
    S = np.zeros((2, 2, 2))
    S[1] = -2.0 * np.eye(2)
    gain = np.empty(2)
    kernels.gains_of(S, gain)
    assert gain[0] == 0.0 and gain[1] == -np.inf


def test_default_is_a_local_optimum_and_beats_random():
    """No single swap (chosen ↔ unchosen) raises log det M: the DETMAX fixed point."""
    G = blocks(3)
    sel = select_default(G, 8)
    assert len(set(sel.chosen.tolist())) == 8
    best = log_det_information(G, sel.chosen)
    for i in sel.chosen:
        for j in np.setdiff1d(np.arange(len(G)), sel.chosen):
            trial = np.where(sel.chosen == i, j, sel.chosen)
            assert log_det_information(G, trial) <= best + 1e-8
    rng = np.random.default_rng(0)
    rand = [log_det_information(G, select_random(len(G), 8, rng)) for _ in range(50)]
    assert best > max(rand)
    assert sel.indices == observability_indices(G, sel.chosen)


def test_default_pool_path_and_determinism():
    G = blocks(4, N=400, m=3, p=8)
    a = select_default(G, 10, pool=50)
    b = select_default(G, 10, pool=50)
    full = select_default(G, 10)
    assert np.array_equal(a.chosen, b.chosen)
    # the exchange over all candidates repairs a small pool: within 1 % of the full run
    assert log_det_information(G, a.chosen) >= log_det_information(G, full.chosen) - 0.01 * abs(
        log_det_information(G, full.chosen))


@pytest.mark.parametrize("work_size", [40, 600])
def test_working_set_exchange_stops_where_the_exchange_over_all_candidates_would(work_size):
    """The DETMAX stop rule checked by brute force over all N = 600 candidates: the best
    candidate to add, once added, is itself the best pose to remove (or no swap gains),
    also when the updates ran on working sets of 40 (several rounds) instead of all N."""
    G = np.ascontiguousarray(blocks(5, N=600, m=2, p=6))
    start = list(range(0, 80, 10))
    chosen, exchanges, _ = _detmax_exchange(G, G.reshape(-1, 6), list(start), 500, work_size, None)
    assert exchanges > 0 and len(set(chosen)) == len(start)
    M = information_matrix(G, chosen)
    ld = np.linalg.slogdet(M)[1]
    others = np.setdiff1d(np.arange(len(G)), chosen)
    gains = [np.linalg.slogdet(M + G[j].T @ G[j])[1] - ld for j in others]
    k = int(others[int(np.argmax(gains))])
    M2 = M + G[k].T @ G[k]
    pool = chosen + [k]
    after = [np.linalg.slogdet(M2 - G[i].T @ G[i])[1] for i in pool]
    r = int(np.argmax(after))
    assert pool[r] == k or after[r] - ld <= 1e-10
    assert log_det_information(G, chosen) > log_det_information(G, start)


def test_default_at_least_as_good_as_cuckoo_and_detmax_on_O1():
    G = blocks(5, N=80, m=2, p=6)
    X = np.random.default_rng(0).random((80, 6))
    d = select_default(G, 7).indices["O1"]
    c = select_cuckoo(G, 7, positions=X, index="O1", rng=np.random.default_rng(1), generations=5).indices["O1"]
    m = select_detmax(G, 7, index="O1", rng=np.random.default_rng(1)).indices["O1"]
    assert d >= c - 1e-12
    assert d >= m - 1e-9


def test_detmax_and_cuckoo_are_seeded_and_improve_their_index():
    G = blocks(6, N=70, m=2, p=5)
    X = np.random.default_rng(0).random((70, 6))
    a = select_detmax(G, 6, index="O4", rng=np.random.default_rng(9))
    b = select_detmax(G, 6, index="O4", rng=np.random.default_rng(9))
    assert np.array_equal(a.chosen, b.chosen)
    start = np.random.default_rng(9).choice(70, size=6, replace=False)  # its initial set (step i)
    assert a.indices["O4"] >= observability_indices(G, start)["O4"]
    c1 = select_cuckoo(G, 6, positions=X, rng=np.random.default_rng(2), generations=4)
    c2 = select_cuckoo(G, 6, positions=X, rng=np.random.default_rng(2), generations=4)
    assert np.array_equal(c1.chosen, c2.chosen) and c1.criterion == "O4"


def test_levy_steps_heavy_tailed():
    s = levy_steps(np.random.default_rng(0), 200_000)
    # Lévy-stable with β = 1.5: far more mass beyond 10 scale units than a Gaussian (P ≈ 0);
    # the fraction is ≈ 0.0125 with a binomial se of 2.5e-4 over 200 000 draws, so the band
    # is ≥ 30 se wide on either side
    assert 0.005 < np.mean(np.abs(s) > 10) < 0.1


def test_selection_errors():
    G = blocks(7, N=10, m=1, p=4)
    with pytest.raises(PkmcalError, match="cannot select"):
        select(G, 11)
    with pytest.raises(PkmcalError, match="at least 4 poses"):
        select_default(G, 3)
    with pytest.raises(PkmcalError, match="unknown selection algorithm"):
        select(G, 5, algorithm="magic")
    with pytest.raises(PkmcalError, match="unknown observability index"):
        select(G, 5, index="O7")


def test_default_with_another_index_polishes_the_d_optimal_set():
    G = blocks(8, N=90, m=2, p=5)
    d = select(G, 6)
    d4 = select(G, 6, index="O4")
    assert d.criterion == "O1" and d4.criterion == "O4"
    assert d4.indices["O4"] >= d.indices["O4"]


# -- end to end on paper 2's prototype -------------------------------------------------------


@pytest.fixture(scope="module")
def machine():
    return stewart_prototype()


@pytest.mark.parametrize("setup_name,algorithm", [("indicators-prototype", "default"),
                                                  ("full-pose-paper1", "corners"),
                                                  ("laser-tracker", "random")])
def test_planned_poses_are_reachable_and_measurable(machine, setup_name, algorithm):
    setup = load_setup(setup_name)
    plan = plan_poses(machine, setup, 16, algorithm=algorithm, n_candidates=300, seed=3, margin=0.1)
    assert plan.poses.shape == (16, 6)
    # independent of the planner: the machine's own limit check, with the margin
    assert machine.check_limits(plan.poses, margin=0.1).ok.all()
    assert np.allclose(plan.commands, machine.ik(plan.poses))
    assert np.all((plan.commands >= machine.stroke[:, 0]) & (plan.commands <= machine.stroke[:, 1]))
    fk = machine.fk(plan.commands, guess=plan.poses)
    assert fk.all_converged and np.allclose(fk.poses, plan.poses, atol=1e-8)
    readings = setup.sensor.predict(machine.frame(plan.poses))            # raises if the sensor cannot read a pose
    assert np.all(np.isfinite(readings))
    assert pose_set_indices(machine, setup, plan.poses, model=plan.model) == pytest.approx(plan.indices)


def test_plan_is_reproducible(machine):
    setup = load_setup("indicators-prototype")
    a = plan_poses(machine, setup, 12, algorithm="random", n_candidates=200, seed=11)
    b = plan_poses(machine, setup, 12, algorithm="random", n_candidates=200, seed=11)
    assert np.array_equal(a.poses, b.poses)


def test_cli_plan_and_observability(machine, tmp_path):
    out = tmp_path / "poses.csv"
    runner = CliRunner()
    res = runner.invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "14",
                              "--n-candidates", "300", "--seed", "2", "-o", str(out), "--units-comment"])
    assert res.exit_code == 0, res.output
    table = read_table(out, ["x", "y", "z", "a", "b", "c"] + [f"lambda{i}" for i in range(1, 7)])
    poses = table[["x", "y", "z", "a", "b", "c"]].copy()
    poses[:, 3:] = np.deg2rad(poses[:, 3:])
    assert machine.check_limits(poses, margin=0.1).ok.all()
    assert np.allclose(table[[f"lambda{i}" for i in range(1, 7)]], machine.ik(poses), atol=1e-9)
    res = runner.invoke(cli, ["observability", "stewart-prototype", "--setup", "full-pose-paper1", "--poses", str(out),
                              "--json"])
    assert res.exit_code == 0, res.output
    ind = json.loads(res.output)
    assert set(ind) >= {"O1", "O2", "O3", "O4", "O5"} and ind["O1"] > 0
    # the indices printed by plan are those of the written poses
    assert f"O1 = {ind['O1']:.6g}" in out.read_text()
    # user errors: one line, exit code 2
    res = runner.invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "99",
                              "--algorithm", "corners", "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "only 64 candidates" in res.output


def test_grid_candidates_plan(machine):
    setup = load_setup("full-pose-paper1")
    plan = plan_poses(machine, setup, 10, grid=3, seed=0)
    assert plan.candidates.kind == "grid" and plan.candidates.n_tested == 3**6
    assert machine.check_limits(plan.poses, margin=0.1).ok.all()
    assert sum(plan.candidates.rejected.values()) >= 3**6 - len(plan.candidates.poses)


def test_planar_redundant_machine_plans_with_the_projection_method():
    from pkmcal.mechanisms.planar import planar_3dof_4act
    from pkmcal.sensors import MeasurementSetup, NoiseModel
    from pkmcal.sensors.planar_tool import PlanarToolSensor

    mech = planar_3dof_4act()
    setup = MeasurementSetup(PlanarToolSensor(n_pose=3), NoiseModel(np.full(2, 0.005), np.array(0.001)))
    plan = plan_poses(mech, setup, 8, n_candidates=200, seed=0)
    rand = plan_poses(mech, setup, 8, algorithm="random", n_candidates=200, seed=0)
    assert plan.model.method == "projection" and plan.poses.shape == (8, 3)
    assert mech.check_limits(plan.poses).ok.all()
    assert plan.indices["O1"] > rand.indices["O1"] > 0
