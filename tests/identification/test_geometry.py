"""Readable geometry (issue 11 item 8): the gauge-free view of an identified machine.

Checked against independent constructions: a rigid motion of a joint set leaves nothing
after alignment and no distance changed; a small non-rigid change is what the projector
onto the complement of the rigid motions keeps (first order); the σ of the aligned points,
of the distances and of the leg lengths agree with Monte Carlo draws of the parameters; the
command prints the section and its JSON.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from pkmcal.identification.geometry import align_rigidly, readable_geometry, rigid_motion_basis
from pkmcal.mechanisms.library import builtin_machine


@pytest.fixture(scope="module")
def nominal():
    return builtin_machine("stewart-prototype")


def _with_points(mech, labels, points):
    rho = mech.params.copy()
    names = list(mech.param_names)
    for lab, p in zip(labels, points):
        for k, a in enumerate("xyz"):
            rho[names.index(f"{lab}.{a}")] = p[k]
    return mech.with_params(rho)


def _points(mech, labels):
    names = list(mech.param_names)
    return np.array([[mech.params[names.index(f"{lab}.{a}")] for a in "xyz"] for lab in labels])


def test_rigid_motion_of_a_joint_set_leaves_no_change(nominal):
    labels = nominal.point_sets["base joints"]
    rot = Rotation.from_rotvec([0.01, -0.02, 0.015])
    shift = np.array([3.0, -2.0, 1.5])
    p0 = _points(nominal, labels)
    moved = _with_points(nominal, labels, rot.apply(p0) + shift)
    g = readable_geometry(nominal, moved)
    base = g.sets[0]
    assert base.name == "base joints"
    scale = np.abs(p0).max()
    assert np.abs(base.moved).max() < 1e-12 * scale
    assert base.rotation_deg == pytest.approx(np.degrees(rot.magnitude()), rel=1e-9)
    assert all(abs(d.change) < 1e-9 for d in base.distances)
    assert len(base.distances) == 15
    plat = g.sets[1]
    assert np.abs(plat.moved).max() == 0.0 and plat.rotation_deg == pytest.approx(0.0, abs=1e-6)
    # readings are physical: leg lengths at the home readings do not see the rigid motion
    assert all(abs(d.change) < 1e-9 for d in g.leg_lengths_at_home)


def test_small_non_rigid_change_is_its_projection_off_the_rigid_motions(nominal):
    labels = nominal.point_sets["platform joints"]
    p0 = _points(nominal, labels)
    rng = np.random.default_rng(3)
    eps = 1e-4                                  # mm: second-order terms ~ eps²/scale
    delta = rng.standard_normal((6, 3)) * eps
    g = readable_geometry(nominal, _with_points(nominal, labels, p0 + delta))
    Q, _ = np.linalg.qr(rigid_motion_basis(p0))
    expected = (delta.ravel() - Q @ (Q.T @ delta.ravel())).reshape(6, 3)
    scale = np.abs(p0).max()
    # second order: the rotation removed is ~eps/scale, its square times the scale is
    # eps²/scale (measured 1.08 eps²/scale at eps = 1e-2 … 1e-4); rounding ~1e-14 × scale
    assert np.abs(g.sets[1].moved - expected).max() < 3 * eps ** 2 / scale + 1e-14 * scale
    # the projected part is not zero: a real change stays visible
    assert np.abs(expected).max() > 0.1 * eps


def test_rigid_basis_columns_are_rigid_motions(nominal):
    p0 = _points(nominal, nominal.point_sets["base joints"])
    B = rigid_motion_basis(p0)
    omega = np.array([0.3, -0.1, 0.2])
    v = np.array([1.0, 2.0, -0.5])
    np.testing.assert_allclose(B @ np.concatenate([v, omega]), (v + np.cross(omega, p0)).ravel(), atol=1e-12)


def test_align_rigidly_is_exact_for_a_rigid_copy():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-100, 100, (6, 3))
    rot = Rotation.from_euler("xyz", [10, -20, 30], degrees=True)
    copy = rot.apply(pts) + [5, 6, 7]
    aligned, angle, _ = align_rigidly(copy, pts)
    np.testing.assert_allclose(aligned, pts, atol=1e-10)
    assert angle == pytest.approx(rot.magnitude() * 180 / np.pi, rel=1e-9)


def test_sigmas_agree_with_monte_carlo(nominal):
    """σ of the aligned points, the distances and the leg lengths (linear propagation of the
    machine covariance) against the spread of 4000 seeded draws of the parameters. The
    covariance is small (σ ≤ 0.01 mm), so linearisation errors are ~σ/scale ≈ 1e-4 of the
    σ; the sampling error of a standard deviation is 1/√(2n) ≈ 1.1 %; tolerance 6 %."""
    rng = np.random.default_rng(11)
    P = len(nominal.param_names)
    A = rng.standard_normal((P, P)) * 0.004
    cov = A @ A.T
    calibrated = nominal.with_params(nominal.params, covariance=cov)
    g = readable_geometry(nominal, calibrated, "test")
    draws = rng.multivariate_normal(nominal.params, cov, size=4000)
    labels = nominal.point_sets["base joints"]
    names = list(nominal.param_names)
    idx = np.array([[names.index(f"{lab}.{a}") for a in "xyz"] for lab in labels])
    p0 = nominal.params[idx]
    moved = np.array([align_rigidly(d[idx], p0)[0] - p0 for d in draws])
    np.testing.assert_allclose(g.sets[0].moved_std, moved.std(axis=0), rtol=0.06)
    d12 = np.linalg.norm(draws[:, idx[0]] - draws[:, idx[1]], axis=1)
    assert g.sets[0].distances[0].name == "b1–b2"
    assert g.sets[0].distances[0].std == pytest.approx(d12.std(), rel=0.06)
    L0 = draws[:, [names.index(f"L0_{i + 1}") for i in range(6)]]
    gain = draws[:, [names.index(f"gain_{i + 1}") for i in range(6)]]
    # leg length at fixed readings λ = L0 + g λ (gain g: mm of leg per reading unit)
    lam = nominal.ik(nominal.home_pose)[0]
    np.testing.assert_allclose([d.std for d in g.leg_lengths_at_home], (L0 + gain * lam).std(axis=0), rtol=0.06)


def test_identify_prints_geometry_and_json(tmp_path):
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    run = CliRunner()
    poses, meas, cal = (str(tmp_path / n) for n in ("p.csv", "m.csv", "cal.yaml"))
    for args in (["plan", "stewart-prototype", "--setup", "full-pose-paper1", "--n-poses", "25", "--seed", "1", "-o", poses],
                 ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "full-pose-paper1",
                  "--poses", poses, "--seed", "2", "-o", meas]):
        assert run.invoke(cli, args).exit_code == 0
    out = run.invoke(cli, ["identify", "stewart-prototype", meas, "--setup", "full-pose-paper1", "-o", cal])
    assert out.exit_code == 0, out.output
    assert "geometry without the gauge" in out.output and "joint-to-joint distances" in out.output
    out = run.invoke(cli, ["identify", "stewart-prototype", meas, "--setup", "full-pose-paper1", "-o", cal, "--json"])
    d = json.loads(out.output)["geometry"]
    assert [s["set"] for s in d["sets"]] == ["base joints", "platform joints"]
    assert len(d["sets"][0]["points"]) == 6 and len(d["leg_lengths_at_home"]) == 6
    assert all(p["moved_std_mm"] is not None for p in d["sets"][1]["points"])
