"""Plans on the study backends (planning/executors.py): the same plan in this process and on
1 or 2 worker processes; the bounded look-ahead map (order, laziness, cancellation); the
selection's passes over all candidates in slices against the one GEMM they replace; the
per-axis workspace bisection done for all axes at once against the one-axis loop."""

import numpy as np
import pytest

from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.parallel import IN_PROCESS
from pkmcal.planning import candidates as cand_mod
from pkmcal.planning import selection as sel_mod
from pkmcal.planning.executors import chunk_map, ordered_map
from pkmcal.planning.plan import plan_poses


@pytest.fixture(scope="module")
def machine():
    return stewart_prototype()


@pytest.fixture(scope="module")
def indicators():
    return load_setup("indicators-prototype")


def test_one_and_two_worker_processes_give_the_in_process_plan(machine, indicators):
    kw = dict(n_candidates=1500, seed=3, chunk_size=700)      # several chunks per round
    ref = plan_poses(machine, indicators, 20, **kw)
    for workers in (1, 2):
        with chunk_map(workers) as run:
            p = plan_poses(machine, indicators, 20, chunk_map=run, **kw)
        np.testing.assert_array_equal(p.poses, ref.poses)
        np.testing.assert_array_equal(p.candidates.poses, ref.candidates.poses)
        assert (p.candidates.n_tested, p.candidates.rejected) == (ref.candidates.n_tested, ref.candidates.rejected)
        assert p.selection.indices == ref.selection.indices


class _Future:
    def __init__(self, value, log):
        self.value, self.log, self.cancelled = value, log, False

    def cancel(self):
        self.cancelled = True
        self.log.append(("cancel", self.value))
        return True


def test_ordered_map_keeps_order_and_a_bounded_look_ahead():
    log, futures = [], []

    def submit(fn, x):
        log.append(("submit", x))
        futures.append(_Future(fn(x), log))
        return futures[-1]

    run = ordered_map(submit, lambda f: f.value, depth=3)
    out = []
    for y in run(lambda x: 10 * x, iter(range(8))):
        out.append(y)
        submitted = sum(1 for e in log if e[0] == "submit")
        assert submitted - len(out) <= 2            # never more than depth in flight
    assert out == [10 * x for x in range(8)]
    log.clear()
    gen = run(lambda x: x, iter(range(100)))
    assert next(gen) == 0
    gen.close()                                     # the consumer stops: the rest is cancelled, not drawn
    assert [e for e in log if e[0] == "cancel"] == [("cancel", 1), ("cancel", 2)]
    assert sum(1 for e in log if e[0] == "submit") == 3


def test_in_process_chunk_map_is_the_builtin_map():
    for workers in (None, 1):
        with chunk_map(workers) as run:
            assert run is IN_PROCESS is map


def _pass_problem(N, p=13):
    rng = np.random.default_rng(N)
    G = rng.normal(size=(N, 6, p)) * np.logspace(-3, 3, p)
    flat = G.reshape(-1, p)
    return G, flat, flat.T @ flat + np.eye(p)


@pytest.mark.parametrize("N", [1, 7, sel_mod._PASS_ROWS, 2 * sel_mod._PASS_ROWS + 3])
def test_passes_in_slices_are_the_one_gemm_they_replace(N):
    # Not bit for bit: BLAS may compute a row with another kernel when the rows around it
    # change (seen on an AMD EPYC: 2 of 10,003 candidates differed in the last bits). Each
    # computation of W = G L⁻ᵀ has entry errors ≤ γ_p (|G||L⁻ᵀ|)_ij (γ_p ≈ p ε), and each
    # of S = W Wᵀ adds ≤ γ_p ‖w_i‖‖w_j‖; the two computations differ by at most twice that.
    G, flat, M = _pass_problem(N)
    p = flat.shape[1]
    Linv = np.linalg.inv(np.linalg.cholesky(M))
    W = flat @ Linv.T                                # the former single GEMM over all rows
    lev = np.einsum("ij,ij->i", W, W).reshape(N, -1).sum(axis=1)
    W3 = W.reshape(N, 6, -1)
    S = np.einsum("nip,njp->nij", W3, W3, optimize=True)
    gamma = 2 * p * np.finfo(float).eps
    w = np.linalg.norm(W3, axis=2)                                   # ‖w_i‖ (N, 6)
    e = gamma * np.linalg.norm((np.abs(flat) @ np.abs(Linv.T)).reshape(N, 6, -1), axis=2)   # ‖Δw_i‖ bound
    bound = 2 * (e[:, :, None] * w[:, None, :] + w[:, :, None] * e[:, None, :]
                 + gamma * w[:, :, None] * w[:, None, :])
    Minv, S2 = sel_mod._all_S(flat, N, 6, M)
    assert np.all(np.abs(S2 - S) <= bound)
    lev_bound = 2 * np.sum(2 * e * w + gamma * w**2, axis=1)
    assert np.all(np.abs(sel_mod._leverages(flat, N, M) - lev) <= lev_bound)
    np.testing.assert_allclose(Minv, np.linalg.inv(M), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(S2[0], G[0] @ np.linalg.solve(M, G[0].T), rtol=1e-9, atol=1e-12)
    gains = np.empty(N)
    sel_mod._kernels().gains_of(S2, gains)
    # _all_gains forms S_j = W_j W_jᵀ in its kernel, summing in another order: |ΔS_ik| ≤
    # γ_p ‖w_i‖‖w_k‖ each way, and d log det(I + S) = tr((I + S)⁻¹ dS) ≤ Σ|dS_ik| for S ⪰ 0;
    # plus the rounding of the two Cholesky factorisations and logs (m ε per pivot).
    gain_bound = 2 * gamma * w.sum(axis=1) ** 2 + 4 * 6 * np.finfo(float).eps * (1 + np.abs(gains))
    assert np.all(np.abs(sel_mod._all_gains(flat, N, 6, M) - gains) <= gain_bound)
    np.testing.assert_allclose(gains, np.linalg.slogdet(np.eye(6) + S)[1], rtol=1e-12, atol=1e-12)


def test_passes_and_updates_give_the_same_bits_on_any_number_of_threads():
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one thread only on this machine: nothing to compare")
    N = 2 * sel_mod._PASS_ROWS + 3
    G, flat, M = _pass_problem(N, p=42)
    before = numba.get_num_threads()
    results = []
    try:
        for threads in (1, numba.config.NUMBA_NUM_THREADS):
            numba.set_num_threads(threads)
            state = sel_mod._DState(np.ascontiguousarray(G), M)
            state.update(3, 1.0)
            state.update(N - 2, 1.0)
            state.update(3, -1.0)
            results.append((sel_mod._all_S(flat, N, 6, M)[1], sel_mod._leverages(flat, N, M),
                            sel_mod._all_gains(flat, N, 6, M), state.S.copy(), state.gains()))
    finally:
        numba.set_num_threads(before)
    for one, many in zip(*results):
        np.testing.assert_array_equal(one, many)


def test_bisection_of_all_axes_at_once_is_the_one_axis_bisection():
    rng = np.random.default_rng(0)
    limits = np.r_[rng.uniform(0, 1, 5), 1.5, 0.0]     # some pass at t = 1, one nowhere
    calls = []

    def ok_all(t):
        calls.append(t.copy())
        return t <= limits

    got = cand_mod._bisect_scales(ok_all, len(limits))
    want = [cand_mod._bisect_scale(lambda t, c=c: t <= c) for c in limits]
    np.testing.assert_array_equal(got, want)
    assert len(calls) == 25                          # one check per halving, not one per axis and halving
    assert np.all(got <= limits) and np.all(np.minimum(limits, 1.0) - got <= 2.0**-24)


def test_workspace_box_is_unchanged_by_the_batched_bisection(machine, indicators):
    from pkmcal.planning.margins import planning_machine, resolve_margin

    pm = planning_machine(machine, resolve_margin(machine))        # the limits bind: the bisection runs
    box = cand_mod.workspace_box(pm, indicators, margin=0.0)
    half = pm.reach_search_shape()
    home = np.asarray(pm.home_pose)
    for i in range(6):
        e = np.zeros(6)
        e[i] = half[i]

        def ok(t, e=e):
            pts = np.stack([home + t * e, home - t * e])
            return bool(cand_mod.check_candidates(pm, indicators, pts, margin=0.0).ok.all())

        assert box[i, 1] == home[i] + cand_mod._bisect_scale(ok) * half[i]
    assert np.any(box[:, 1] - home < half)


def _plan_cli(tmp_path, name, *extra):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    out = tmp_path / f"{name}.csv"
    res = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "12",
                                   "--n-candidates", "400", "--seed", "2", "-o", str(out), "-q", *extra])
    return res, out


def test_plan_command_workers_give_the_same_file(tmp_path):
    ref, ref_out = _plan_cli(tmp_path, "ref")
    two, two_out = _plan_cli(tmp_path, "two", "--workers", "2")
    assert ref.exit_code == 0 and two.exit_code == 0, (ref.output, two.output)
    assert two_out.read_bytes() == ref_out.read_bytes()


def test_plan_command_workers_with_a_dask_scheduler_is_an_error(tmp_path):
    res, out = _plan_cli(tmp_path, "bad", "--workers", "2", "--dask", "tcp://127.0.0.1:1")
    assert res.exit_code == 2 and "--workers applies to local runs" in res.output and not out.exists()


def test_plan_on_a_dask_local_cluster_is_the_in_process_plan(machine, indicators):
    pytest.importorskip("distributed")
    kw = dict(n_candidates=900, seed=5, chunk_size=400)
    ref = plan_poses(machine, indicators, 15, **kw)
    with chunk_map(2, "local") as run:
        p = plan_poses(machine, indicators, 15, chunk_map=run, **kw)
    np.testing.assert_array_equal(p.poses, ref.poses)
    assert p.candidates.rejected == ref.candidates.rejected and p.selection.indices == ref.selection.indices
