"""ISO 230-4 circle figures (pkmcal.identification.iso230_4): by hand, the least-squares
centre's removal, the uncertainty against Monte Carlo, and the circle found in a plan."""

from __future__ import annotations

import numpy as np
import pytest

from helpers import mc_std_ratio_band
from pkmcal.api import load_machine
from pkmcal.identification.iso230_4 import circle_angles, circle_figures


def test_figures_by_hand():
    """r = 0.01 cos φ + 0.002 cos 2φ at 36 points: F_max = 0.012 (φ = 0), F_min = −0.008
    (φ = π); the centre offset (0.01, 0) is removed by the least-squares circle, leaving
    0.002 cos 2φ: G = 0.004 (orthogonal to 1, cos φ, sin φ on the uniform grid)."""
    phi = 2 * np.pi * np.arange(36) / 36
    rep = circle_figures(phi, 0.01 * np.cos(phi) + 0.002 * np.cos(2 * phi), 1e-4)
    assert rep.get("F_max").value == pytest.approx(0.012, abs=1e-15)
    assert rep.get("F_min").value == pytest.approx(-0.008, abs=1e-15)
    assert rep.get("G").value == pytest.approx(0.004, abs=1e-15)
    assert rep.get("F_max").U == pytest.approx(2e-4, rel=1e-12)     # one reading: 2σ


def test_uncertainty_against_monte_carlo():
    """8 points whose extremes stand far above the noise (σ = 1 µm against 10 µm steps): U/2
    matches the spread of 2000 noisy repetitions (χ² band) and covers the noise-free figures."""
    phi = 2 * np.pi * np.arange(8) / 8
    true = 0.03 * np.cos(phi) + 0.01 * np.cos(2 * phi) + 0.004 * np.sin(3 * phi) + 0.006 * np.cos(3 * phi)
    sigma = 1e-3
    ref = circle_figures(phi, true, sigma)
    rng = np.random.default_rng(3)
    reps = [circle_figures(phi, true + rng.normal(scale=sigma, size=8), sigma) for _ in range(2000)]
    lo, hi = mc_std_ratio_band(2000, 3)
    for name in ("F_max", "F_min", "G"):
        d = np.array([r.get(name).value for r in reps]) - ref.get(name).value
        U = np.array([r.get(name).U for r in reps])
        assert lo < d.std(ddof=1) / (ref.get(name).U / 2) < hi, name
        assert (np.abs(d) <= U).mean() >= 0.93, name
        assert not ref.get(name).note


def test_circle_found_in_a_plan():
    """The poses of ``plan --algorithm circle`` (the ballbar's circle frames) give back the
    angles 0, 2π/n, …; moved off the circle, they are refused with the reason."""
    from pathlib import Path

    from pkmcal.api import load_setup

    m = load_machine("stewart-prototype")
    setup = load_setup(Path(__file__).resolve().parents[2] / "examples" / "setup-ballbar.yaml", m)
    frames = setup.sensor.circle_frames(12, m.frame(m.home_pose[None]))
    poses = m.poses_from_frame(frames)
    phi = circle_angles(m, setup.sensor, poses)
    assert np.allclose(np.mod(phi, 2 * np.pi), 2 * np.pi * np.arange(12) / 12, atol=1e-12)
    poses[3, 0] += 0.1
    assert "not on one circle" in circle_angles(m, setup.sensor, poses)
