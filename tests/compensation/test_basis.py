"""The fields' bases (pkmcal.compensation.basis), by properties that need no Klipper (its own
ZMesh is the referee in tests/controllers/test_klipper_mesh.py): a Klipper mesh passes through
its heights at its nodes whatever the algorithm, reproduces a plane exactly (Lagrange always;
a cardinal spline at tension 1/2, Catmull-Rom, between its end segments — not at Klipper's
default 0.2, whose tangents are 0.4 of the chord's),
holds its edge value outside; a round bed's corners repeat each row's end nodes inside the
radius (bed_mesh.py probe_finalize); a polynomial basis has (d+n choose n) monomials, 1 and 0
at the box's centre."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pkmcal.compensation.basis import MeshBasis, PolynomialBasis
from pkmcal.errors import PkmcalError


@given(st.integers(3, 7), st.integers(3, 7), st.sampled_from(["lagrange", "bicubic", "direct"]),
       st.integers(0, 4), st.integers(0, 2**32 - 1))
def test_mesh_passes_through_its_nodes(nx, ny, algo, pps, seed):
    b = MeshBasis(nx, ny, ((-40.0, 60.0), (10.0, 90.0)), algo, 0.2, pps)
    Z = np.random.default_rng(seed).normal(size=b.size)
    xs, ys = np.linspace(-40, 60, nx), np.linspace(10, 90, ny)
    nodes = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)       # row order: y, then x
    np.testing.assert_allclose(b.values(nodes) @ Z, Z, atol=1e-12)


@pytest.mark.parametrize("algo, n", [("lagrange", 3), ("lagrange", 5), ("bicubic", 4), ("bicubic", 7)])
def test_mesh_reproduces_a_plane_and_holds_its_edges(algo, n):
    b = MeshBasis(n, n, ((0.0, 100.0), (0.0, 50.0)), algo, tension=0.5)
    xs, ys = np.linspace(0, 100, n), np.linspace(0, 50, n)
    X, Y = np.meshgrid(xs, ys)
    Z = (0.01 * X - 0.02 * Y + 0.3).reshape(-1)
    pts = np.random.default_rng(1).uniform([0, 0], [100, 50], (200, 2))
    plane = 0.01 * pts[:, 0] - 0.02 * pts[:, 1] + 0.3
    if algo == "lagrange":
        np.testing.assert_allclose(b.values(pts) @ Z, plane, atol=1e-12)
    else:   # the end segments repeat their end node (a flat tangent there): a plane only inside them
        inner = (pts[:, 0] > 100 / (n - 1)) & (pts[:, 0] < 100 - 100 / (n - 1)) & \
                (pts[:, 1] > 50 / (n - 1)) & (pts[:, 1] < 50 - 50 / (n - 1))
        np.testing.assert_allclose((b.values(pts) @ Z)[inner], plane[inner], atol=1e-12)
    out = np.array([[-30.0, 20.0], [0.0, 20.0], [150.0, 60.0], [100.0, 50.0]])
    v = b.values(out) @ Z
    assert v[0] == pytest.approx(v[1], abs=1e-12) and v[2] == pytest.approx(v[3], abs=1e-12)


def test_round_bed_corners_repeat_the_row_ends():
    b = MeshBasis(5, 5, ((-90.0, 90.0), (-90.0, 90.0)), "bicubic", radius=90.0)
    xs = np.linspace(-90, 90, 5)
    inside = np.hypot(xs[None, :], xs[:, None]) <= 90.0
    assert b.size == inside.sum() == 13
    full = b.expand(np.arange(1.0, b.size + 1.0)).reshape(5, 5)
    for j in range(5):
        cols = np.flatnonzero(inside[j])
        assert np.all(full[j, :cols[0]] == full[j, cols[0]]) and np.all(full[j, cols[-1] + 1:] == full[j, cols[-1]])
        assert len(set(full[j, cols])) == len(cols)                      # the inside nodes are free
    with pytest.raises(PkmcalError, match="odd"):
        MeshBasis(4, 4, ((-90.0, 90.0), (-90.0, 90.0)), radius=90.0)


@pytest.mark.parametrize("degree, dims", [(0, 3), (1, 3), (2, 6), (3, 3)])
def test_polynomial_basis(degree, dims):
    box = tuple((-1.0 - k, 3.0 + k) for k in range(dims))
    b = PolynomialBasis(degree, box)
    assert b.size == comb(degree + dims, dims)
    centre = np.array([[np.mean(r) for r in box]])
    np.testing.assert_array_equal(b.values(centre)[0], np.r_[1.0, np.zeros(b.size - 1)])
    corner = np.array([[r[1] for r in box]])                               # every scaled coordinate 1
    np.testing.assert_allclose(b.values(corner)[0], 1.0)
