"""Merlet's |J⁻¹| and the inverse condition number of a pose (paper 2 §2.1; issue 15 item 2).

Independent checks: |det| equals the product of the singular values of the scaled inverse
Jacobian built here from the legs (u_i, (R a_i) × u_i); the prototype's three-fold symmetry
(a pose turned by 120° about z has the same measures); both vanish at the 6-6 platform's
rotation singularity (yaw 90°, by construction of the symmetric joint pairs); |det| scales
as L⁻³ with the length L of the rotation columns, the inverse condition number does not
scale as a whole.
"""

from __future__ import annotations

import numpy as np
import pytest

from pkmcal.conventions import euler_to_matrix, matrix_to_euler
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms import builtin_machine
from pkmcal.planning.indices import singularity_measures


@pytest.fixture(scope="module")
def machine():
    return builtin_machine("stewart-prototype")


def _poses(m, n=20, seed=0):
    return m.home_pose + np.random.default_rng(seed).uniform(-1, 1, (n, 6)) * [20, 20, 10, 0.15, 0.15, 0.5]


def test_det_is_the_product_of_singular_values_of_the_leg_jacobian(machine):
    P = _poses(machine)
    out = singularity_measures(machine, P)
    R = euler_to_matrix(P[:, 3:6])
    Ra = np.einsum("nij,kj->nki", R, machine.platform)
    legs = P[:, None, 0:3] + Ra - machine.base
    u = legs / np.linalg.norm(legs, axis=2, keepdims=True)
    J = np.concatenate([u, np.cross(Ra, u) / machine.platform_radius], axis=2)
    s = np.linalg.svd(J, compute_uv=False)
    np.testing.assert_allclose(out["det"], np.prod(s, axis=1), rtol=1e-10)
    np.testing.assert_allclose(out["inverse_condition"], s[:, -1] / s[:, 0], rtol=1e-12)


def test_three_fold_symmetry(machine):
    P = _poses(machine, seed=1)
    t = 2 * np.pi / 3
    Q = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    turned = P.copy()
    turned[:, 0:3] = P[:, 0:3] @ Q.T
    # the joints map onto each other (Q b_i = b_j, Q a_i = a_j), so the whole configuration
    # turned is p' = Q p, R' = Q R Qᵀ: the legs permute and turn with Q
    turned[:, 3:6] = matrix_to_euler(Q @ euler_to_matrix(P[:, 3:6]) @ Q.T)
    a, b = singularity_measures(machine, P), singularity_measures(machine, turned)
    # Table 3's joints are symmetric to its 3 printed decimals (152.5 cos 30° = 132.0689 is
    # printed 132.068): 1e-3 mm in 150 mm, so the measures agree to ~1e-5 relative
    for k in a:
        np.testing.assert_allclose(a[k], b[k], rtol=1e-4)
    assert not np.allclose(a["det"], singularity_measures(machine, P[::-1])["det"], rtol=1e-4)


def test_both_vanish_at_the_rotation_singularity(machine):
    P = np.tile(machine.home_pose, (3, 1))
    P[:, 5] = np.deg2rad([0.0, 60.0, 90.0])
    out = singularity_measures(machine, P)
    assert out["det"][2] < 1e-12 * out["det"][0] and out["inverse_condition"][2] < 1e-12
    assert np.all(np.diff(out["det"]) < 0) and np.all(np.diff(out["inverse_condition"]) < 0)


def test_length_scaling(machine):
    P = _poses(machine, 5, seed=2)
    a = singularity_measures(machine, P, length=70.0)
    b = singularity_measures(machine, P, length=140.0)
    np.testing.assert_allclose(b["det"], a["det"] / 8.0, rtol=1e-10)
    assert not np.allclose(b["inverse_condition"], a["inverse_condition"])
    with pytest.raises(PkmcalError, match="positive number of mm"):
        singularity_measures(machine, P, length=0.0)
