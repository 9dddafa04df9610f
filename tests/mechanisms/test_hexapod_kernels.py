"""The hexapod's two evaluations of the same formulas: NumPy for small batches (no numba
import), the compiled kernels for large ones and for the identification's combined pass.
They must agree to rounding, and which one runs may depend only on the batch size."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pkmcal.mechanisms import hexapod as hexapod_module
from pkmcal.mechanisms.library import stewart_prototype, symmetric_hexapod

from helpers import random_poses

PROTOTYPE = stewart_prototype()
EPS = np.finfo(float).eps


def _poses(machine, n, seed):
    return random_poses(machine, n, seed)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1))
def test_numpy_and_compiled_leg_lengths_agree_to_rounding(seed):
    """A batch just below the threshold (NumPy) and the same poses inside a batch at the
    threshold (kernel): each length is a sum of three products and a square root, so the two
    differ by a few ulp of the leg length; 16 ulp bounds it with margin."""
    n = hexapod_module.COMPILED_FROM
    poses = _poses(PROTOTYPE, n, seed)
    small = PROTOTYPE.leg_lengths(poses[: n - 1])            # NumPy
    large = PROTOTYPE.leg_lengths(poses)[: n - 1]             # compiled
    np.testing.assert_allclose(small, large, rtol=16 * EPS, atol=0)


def test_the_path_depends_only_on_the_batch_size():
    """The same small batch gives the same bits before and after the kernels were used."""
    poses = _poses(PROTOTYPE, 5, 3)
    before = PROTOTYPE.leg_lengths(poses)
    PROTOTYPE.leg_lengths(_poses(PROTOTYPE, 2 * hexapod_module.COMPILED_FROM, 4))   # loads the kernels
    np.testing.assert_array_equal(PROTOTYPE.leg_lengths(poses), before)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 80))
def test_combined_pass_equals_separate_calls(seed, n):
    """``ik_and_jacobians`` (one kernel pass) against ``ik`` and ``actuator_jacobians``: the
    Jacobians come from the same kernel (bit-identical); the readings bit-identical to the
    compiled IK and within rounding of the NumPy one."""
    machine = symmetric_hexapod(base_radius=150.0 + seed % 50, platform_radius=70.0)
    poses = _poses(machine, n, seed)
    q, A, B = machine.ik_and_jacobians(poses)
    A2, B2 = machine.actuator_jacobians(poses)
    np.testing.assert_array_equal(A, A2)
    np.testing.assert_array_equal(B, B2)
    L = machine.leg_lengths(poses)
    if n >= hexapod_module.COMPILED_FROM:
        np.testing.assert_array_equal(q, L - machine.offset)
    np.testing.assert_allclose(q, machine.ik(poses), rtol=0, atol=16 * EPS * np.max(L))
