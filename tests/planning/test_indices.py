"""Observability indices O1..O5 against closed forms and scaling laws (paper 2 §4)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.errors import PkmcalError
from pkmcal.planning.indices import (
    INDEX_NAMES,
    check_index_name,
    index_from_eigenvalues,
    indices_from_singular_values,
    information_matrix,
    log_det_information,
    observability_indices,
    singular_values,
)


def diagonal_blocks(s):
    """One single-row block per parameter: the stacked J is diag(s)."""
    n = len(s)
    G = np.zeros((n, 1, n))
    G[np.arange(n), 0, np.arange(n)] = s
    return G


def test_diagonal_jacobian_closed_forms():
    s = np.array([4.0, 2.0, 1.0, 0.5])
    ind = observability_indices(diagonal_blocks(s))
    assert ind["O1"] == pytest.approx((4 * 2 * 1 * 0.5) ** 0.25 / np.sqrt(4))
    assert ind["O2"] == pytest.approx(0.5 / 4)
    assert ind["O3"] == pytest.approx(0.5)
    assert ind["O4"] == pytest.approx(0.25 / 4)
    assert ind["O5"] == pytest.approx(1 / (1 / 16 + 1 / 4 + 1 + 4))


def test_rank_deficient_gives_zero():
    G = diagonal_blocks(np.array([1.0, 2.0, 3.0]))
    G[:, :, 2] = 0.0
    assert all(v == 0.0 for v in observability_indices(G).values())


@settings(max_examples=30, deadline=None)
@given(st.integers(min_value=0, max_value=10_000), st.integers(min_value=1, max_value=4))
def test_scaling_laws_under_duplication(seed, m):
    """Duplicating every row: σ → √2 σ, rows → 2 rows, so O1, O2 stay; O3, O4 ×√2; O5 ×2."""
    rng = np.random.default_rng(seed)
    G = rng.standard_normal((12, m, 5))
    a = observability_indices(G)
    b = observability_indices(np.concatenate([G, G]))
    assert b["O1"] == pytest.approx(a["O1"], rel=1e-9)
    assert b["O2"] == pytest.approx(a["O2"], rel=1e-9)
    assert b["O3"] == pytest.approx(np.sqrt(2) * a["O3"], rel=1e-9)
    assert b["O4"] == pytest.approx(np.sqrt(2) * a["O4"], rel=1e-9)
    assert b["O5"] == pytest.approx(2 * a["O5"], rel=1e-9)


def test_invariant_to_row_rotation_and_pose_order():
    rng = np.random.default_rng(3)
    G = rng.standard_normal((10, 3, 4))
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    a = observability_indices(G)
    b = observability_indices(np.einsum("ij,njp->nip", Q, G)[::-1])
    for k in INDEX_NAMES:
        assert b[k] == pytest.approx(a[k], rel=1e-10)


def test_eigenvalue_path_matches_svd_path():
    rng = np.random.default_rng(5)
    G = rng.standard_normal((9, 2, 6))
    s = singular_values(G)
    assert np.allclose(s, np.linalg.svd(G.reshape(-1, 6), compute_uv=False))
    M = information_matrix(G)
    assert np.allclose(M, G.reshape(-1, 6).T @ G.reshape(-1, 6))
    ev = np.linalg.eigvalsh(M)[None]
    ref = indices_from_singular_values(s, 18)
    for k in INDEX_NAMES:
        assert index_from_eigenvalues(k, ev, 18)[0] == pytest.approx(ref[k], rel=1e-8)
    assert log_det_information(G) == pytest.approx(2 * np.sum(np.log(s)), rel=1e-10)


def test_subset_and_unknown_index():
    G = np.random.default_rng(1).standard_normal((8, 2, 3))
    assert observability_indices(G, [0, 1, 2]) == observability_indices(G[:3])
    assert check_index_name("o4") == "O4"
    with pytest.raises(PkmcalError, match="O1, O2"):
        check_index_name("O9")
