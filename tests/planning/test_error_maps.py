"""Error maps (paper 1 §IV): zero for the exact machine, linear in small parameter errors,
agreeing with the first-order model, and written as PNG/SVG."""

import numpy as np
import pytest

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.library import stewart_prototype
from pkmcal.planning.candidates import workspace_box
from pkmcal.planning.error_maps import error_slices, plot_error_maps, pose_errors


@pytest.fixture(scope="module")
def machine():
    return stewart_prototype()


def test_zero_error_for_the_nominal_machine(machine):
    poses = machine.home + np.array([[5, -3, 4, 0.02, -0.01, 0.03], [0, 0, 0, 0, 0, 0]])
    e_p, e_o = pose_errors(machine, machine, poses)
    assert np.all(e_p < 1e-8) and np.all(e_o < 1e-10)


def test_linear_in_small_errors_and_matches_first_order(machine):
    """e(2δρ) = 2 e(δρ) and e(δρ) = |A⁻¹B δρ| (first order: IK(x + δx, ρ + δρ) = IK(x, ρ) ⇒
    δx = −A⁻¹ B δρ, A = ∂λ/∂x, B = ∂λ/∂ρ) up to remainders of second order: relative to the
    error they are small and fall in proportion to the parameter error (×0.1 → ×0.1; the
    O(k²) part of that ratio is ~0.1 %, FK's 1e-9 mm ~0.04 % at k = 0.1), a check of the order
    that needs no tolerance on the remainder's size."""
    rng = np.random.default_rng(0)
    d = np.r_[rng.uniform(-0.1, 0.1, 42), np.zeros(6)]  # the geometry; the gains stay 1
    poses = machine.home + rng.uniform(-1, 1, (5, 6)) * np.array([10, 10, 5, 0.03, 0.03, 0.05])
    A = machine.actuator_pose_jacobian(poses)
    B = machine.actuator_param_jacobian(poses)

    def relative_remainders(k):
        e1, _ = pose_errors(machine, machine.with_params(machine.params + k * d), poses)
        e2, _ = pose_errors(machine, machine.with_params(machine.params + 2 * k * d), poses)
        dx = -np.linalg.solve(A, (B @ (k * d))[..., None])[..., 0]
        return np.array([np.max(np.abs(e2 - 2 * e1) / e1), np.max(np.abs(e1 - np.linalg.norm(dx[:, :3], axis=1)) / e1)])

    big, small = relative_remainders(1.0), relative_remainders(0.1)
    assert np.all(big < 1e-2)                      # ±0.1 mm parameter errors: linear to 1 %
    assert np.all((0.08 < small / big) & (small / big < 0.12)), small / big


def test_slices_and_figures(machine, tmp_path):
    box = workspace_box(machine)
    sl = error_slices(machine, box, n_curves=3, n_points=9, rng=np.random.default_rng(1))
    assert sl.position.shape == (6, 3, 9) and sl.values.shape == (6, 9)
    assert np.allclose(sl.values[:, 0], box[:, 0]) and np.allclose(sl.values[:, -1], box[:, 1])
    finite = np.isfinite(sl.position)
    assert finite.any() and np.all(sl.position[finite] < 5.0)          # ±0.1 mm errors: well under 5 mm
    assert np.array_equal(finite, np.isfinite(sl.orientation))
    for ext, magic in ((".png", b"\x89PNG"), (".svg", b"<?xml")):
        path = tmp_path / f"map{ext}"
        plot_error_maps(sl, path)
        assert path.read_bytes().startswith(magic)
    with pytest.raises(PkmcalError, match="png or .svg"):
        plot_error_maps(sl, tmp_path / "map.jpg")
