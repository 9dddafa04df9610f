"""pkmcal's ik-residual fit refereed by an estimator we did not write (issue 24, item 2): paper 1's
campaign, fitted by ``pkmcal identify`` and by the textbook GLS of :mod:`referee_gls` (NumPy and
SciPy only, its own kinematics and derivatives) from the same files.

Paper 1's campaign (Agheli & Nategh §VI; src/pkmcal/reproduce/paper1.py, docs/reproductions.md):
``stewart-prototype``, a real machine with every one of the 42 parameters off by U(−5, 5) mm,
uniform noise ±0.025 mm and ±0.001 rad on the full pose (``full-pose-paper1``) and ±0.01 mm on the
legs, 15 of the 64 corners of the box home ± (15, 15, 8 mm, 6°, 6°, 6°) that the real machine
reaches (its leg-collision check off, as in the reproduction: the prototype's legs nearly touch).
pkmcal makes the files (``pkmcal simulate``) and fits them (``pkmcal identify``); the referee reads
the same machine, setup and measurement files and the real machine's file.
"""

from __future__ import annotations

import itertools
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import referee_gls as rg

BOX_HALF = np.array([15.0, 15.0, 8.0, 6.0, 6.0, 6.0])          # mm, deg (paper1.HEXAPODS' first box)
N_POSES = 15
ERROR_MM = 5.0


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The nominal machine and setup files, and the 64 corners of paper 1's box (mm, deg)."""
    import pkmcal

    folder = tmp_path_factory.mktemp("paper1")
    machine, setup = rg.write_builtins(folder, "stewart-prototype", "full-pose-paper1")
    home = pkmcal.load_machine(machine).home_pose
    home = np.concatenate([home[:3], np.rad2deg(home[3:])])
    corners = [home + BOX_HALF * np.array(s) for s in itertools.product((-1.0, 1.0), repeat=6)]
    poses = folder / "corners.csv"
    poses.write_text("x,y,z,a,b,c\n" + "".join(",".join(repr(float(v)) for v in c) + "\n" for c in corners),
                     encoding="utf-8")
    return folder, machine, setup, poses


def campaign(files, seed: int):
    """Paper 1's campaign number ``seed``: (measurements of 15 reached corners, real machine),
    or None when the real machine reaches fewer than 15 corners."""
    folder, machine, setup, poses = files
    return rg.simulate_reached(folder, machine, setup, poses, seed, N_POSES, ERROR_MM)


def test_referee_derivatives_match_its_own_central_differences(files):
    """The referee's analytic IK derivatives (∂λ/∂x, ∂λ/∂ρ) against its own central
    differences: step 1e-4 mm / 1e-5 rad, truncation h²/6·|λ'''| ≲ 1e-9 (|λ'''| ≲ 1/L² for
    lengths, ≲ |a| = 70 mm for angles, so 70·1e-10/6 ≈ 1e-9) and rounding ε·L/h ≈ 1e-9; the
    gains (λ = (L − L0)/g, |∂³λ/∂g³| = 6|λ|/g³ ≈ 300) step 1e-6: 300·1e-12/6 + ε·40/1e-6 ≈ 1e-8;
    tolerance 1e-7 (mm per mm, mm per rad)."""
    _, machine, _, poses = files
    m = rg.read_hexapod(machine)
    rho = m.params + np.random.default_rng(3).uniform(-5, 5, 48) * np.r_[np.ones(42), np.full(6, 0.01)]
    x = np.loadtxt(poses, delimiter=",", skiprows=1)[:8]
    x[:, 3:] = np.deg2rad(x[:, 3:])
    _, A, B = rg.inverse_kinematics(x, rho, derivatives=True)
    A_fd = rg.central_jacobian(lambda xx: rg.inverse_kinematics(xx, rho), x, rg.POSE_STEPS)
    B_fd = rg.central_jacobian(lambda rr: np.stack([rg.inverse_kinematics(x[n:n + 1], rr[n])[0] for n in range(len(x))]),
                               np.tile(rho, (len(x), 1)), np.r_[np.full(42, 1e-4), np.full(6, 1e-6)])
    assert np.max(np.abs(A - A_fd)) < 1e-7
    assert np.max(np.abs(B - B_fd)) < 1e-7
    # and FK inverts IK: Newton from home lands on the pose (round trip)
    q = rg.inverse_kinematics(x, rho)
    xf, ok = rg.forward_kinematics(q, rho, np.tile(np.r_[0, 0, 315.0, 0, 0, 0], (len(x), 1)))
    assert ok.all() and np.max(np.abs(xf - x)) < 1e-9


def test_referee_imports_no_pkmcal(files, tmp_path):
    """The referee fits a campaign in a process where ``import pkmcal`` fails: it is independent."""
    _, machine, setup, _ = files
    meas, _ = campaign(files, 1)
    code = ("import sys; sys.modules['pkmcal'] = None; sys.path.insert(0, sys.argv[1]); import referee_gls as rg; "
            "ref, fit = rg.referee(sys.argv[2], sys.argv[3], sys.argv[4], 'ik-residual'); "
            "assert 'pkmcal' not in [m.split('.')[0] for m in sys.modules if sys.modules[m] is not None]; "
            "print(len(fit.free), fit.chi2)")
    out = subprocess.run([sys.executable, "-c", code, str(Path(__file__).parents[1]), str(machine), str(setup), str(meas)],
                         capture_output=True, text=True, check=False)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[0] == "42"


def test_paper1_campaign_pkmcal_equals_referee(files, tmp_path):
    """One campaign: pkmcal identify and the referee agree parameter by parameter (all 42)."""
    _, machine, setup, _ = files
    meas, _ = campaign(files, 1)
    fit_json = rg.identify(machine, meas, setup, tmp_path / "cal.yaml")
    ref, fit = rg.referee(machine, setup, meas, "ik-residual")
    assert fit_json["gauge"] == [] and len(fit.free) == 42
    assert ref.rank()[0] == 42
    rg.assert_agree(fit_json, ref, fit, tmp_path / "cal.yaml")


def test_paper1_monte_carlo_efficiency_and_coverage(files, tmp_path):
    """Over K = :func:`referee_gls.trials_needed` (42) = 45 campaigns (derivation there): pkmcal's
    mean squared error in the information metric is the referee's (ratio within 2 %: a 10 %
    loss fails with probability > 0.999), its reported covariance covers its errors
    (:func:`referee_gls.coverage_bands`), and the plain fit pkmcal offers (``--unweighted``,
    the orientation noise and the noise correlations ignored) is caught: it loses more than
    10 % against the referee."""
    _, machine, setup, _ = files
    K = rg.trials_needed(42)
    e_pk, e_ref, e_plain, fishers, d2, inside = [], [], [], [], [], []
    level = rg.stats_chi2_ppf(0.95, 42)
    seed = 100
    while len(e_pk) < K:
        seed += 1
        made = campaign(files, seed)
        if made is None:
            continue
        meas, real = made
        ref, fit = rg.referee(machine, setup, meas, "ik-residual")
        fit_json = rg.identify_api(machine, meas, setup)
        plain = rg.identify_api(machine, meas, setup, weighted=False)
        rg.assert_agree(fit_json, ref, fit)
        m = rg.read_hexapod(real)
        truth = np.array([m.params[m.names.index(n)] for n in fit.free])
        e_pk.append(rg.pkmcal_values(fit_json, fit.free) - truth)
        e_plain.append(rg.pkmcal_values(plain, fit.free) - truth)
        e_ref.append(np.array([fit.value(n) for n in fit.free]) - truth)
        fishers.append(fit.jw)
        d2.append(float(rg.mahalanobis(e_pk[-1][None], fit_json["covariance_prior"][None])[0]))
        inside.append(float(rg.mahalanobis(e_pk[-1][None], fit_json["covariance"][None])[0]) <= level)
    e_pk, e_ref, e_plain, fishers = map(np.array, (e_pk, e_ref, e_plain, fishers))
    ratio = rg.efficiency_ratio(e_pk, e_ref, fishers)
    plain_ratio = rg.efficiency_ratio(e_plain, e_ref, fishers)
    (lo, hi), min_inside = rg.coverage_bands(K, 42)
    summary = (f"K={K}: MSE ratio pkmcal/referee {ratio:.6f}, unweighted/referee {plain_ratio:.4f}; "
               f"mean d² {np.mean(d2):.2f} (band {lo:.2f}..{hi:.2f}); {sum(inside)} of {K} inside the 95 % ellipsoid "
               f"(at least {min_inside})")
    assert abs(ratio - 1.0) <= rg.THRESHOLD - 1.0, summary
    assert plain_ratio > 1.0 + rg.LOSS, summary
    assert lo <= np.mean(d2) <= hi, summary
    assert sum(inside) >= min_inside, summary


#: A full-pose instrument standing off the base and turned, on a tool 40 mm above the platform:
#: as surveyed (the fit's start, its frame and the tool's position free) and as it stands (the
#: simulation's truth); mm and degrees.
SURVEYED_FULL_POSE = """\
sensor: full-pose
world: {x: 350.0, y: -20.0, z: -15.0, a: 0.0, b: 0.0, c: 30.0}
tool: {x: 0.0, y: 0.0, z: 40.0, a: 0.0, b: 0.0, c: 10.0}
free: [world.x, world.y, world.z, world.a, world.b, world.c, tool.x, tool.y, tool.z]
noise: {position: 0.01, orientation_deg: 0.003, actuator: 0.004}
"""
TRUE_FULL_POSE = SURVEYED_FULL_POSE.replace("x: 350.0, y: -20.0, z: -15.0, a: 0.0, b: 0.0, c: 30.0",
                                            "x: 353.5, y: -18.2, z: -12.9, a: 0.8, b: -1.1, c: 31.5") \
                                   .replace("x: 0.0, y: 0.0, z: 40.0", "x: 2.1, y: -1.4, z: 43.0")


def test_any_full_pose_campaign_pkmcal_equals_referee(files, tmp_path):
    """The referee is not built for paper 1's files: a machine whose legs read in half-lengths
    (gain 2, stroke 0–25), an instrument whose frame and tool offset are unknown (free, so
    pkmcal fixes a gauge, which the referee checks), Gaussian noise, and a measurement file
    that starts with a units comment (``simulate --units-comment``): the same agreement."""
    folder, machine, _, poses = files
    text = machine.read_text(encoding="utf-8").replace("  stroke: [0.0, 50.0]", "  stroke: [0.0, 25.0]\n  gain: 2.0")
    assert text.count("gain: 2.0") == 6
    geared = tmp_path / "geared.yaml"
    geared.write_text(text, encoding="utf-8")
    setup, true_setup = tmp_path / "surveyed.yaml", tmp_path / "true.yaml"
    setup.write_text(SURVEYED_FULL_POSE, encoding="utf-8")
    true_setup.write_text(TRUE_FULL_POSE, encoding="utf-8")
    every, real = tmp_path / "every.csv", tmp_path / "real.yaml"
    rg.run_pkmcal("simulate", geared, "--random-errors", ERROR_MM, "--save-real", real, "--setup", true_setup,
                  "--poses", poses, "--seed", 5, "--ignore-limit", "leg_collision", "--units-comment", "-o", every)
    assert open(every, encoding="utf-8").readline().startswith("# units:")
    fit_json = rg.identify(geared, every, setup, tmp_path / "cal.yaml", "--method", "ik-residual")
    gauge = fit_json["gauge"]
    everything, _ = rg.referee(geared, setup, every, "ik-residual")
    assert everything.rank()[0] == len(everything.free) - len(gauge), gauge
    ref, fit = rg.referee(geared, setup, every, "ik-residual", fixed=gauge)
    assert ref.rank()[0] == len(fit.free)
    rg.assert_agree(fit_json, ref, fit, tmp_path / "cal.yaml")
