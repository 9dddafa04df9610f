"""pkmcal's fk-residual fit of a dial-indicator campaign (paper 2, ``indicators-prototype``) refereed
by the textbook GLS of :mod:`referee_gls` on the same files (issue 24, item 2): the referee's own
forward kinematics (Newton on the pose) and its own indicator model, written from the definition
in src/pkmcal/sensors/indicators.py and docs/file-formats.md — indicator k at (x_k, y_k) on the
plate reads, along the plate's z, the height of the platform's lower plane (normal R e_z, the
platform origin ``plane_offset`` above it), less its zero.

The campaign (paper 2 §4): ``stewart-prototype``, a real machine with every parameter off by
U(−5, 5) mm, three indicators at radius 40 mm (σ 0.01 mm, legs 0.005 mm), 45 poses the real
machine reaches of the 60 O1-optimal poses ``pkmcal plan`` chooses for the nominal one. Three
directions are invisible to indicators (the platform joints moved rigidly in the platform's plane)
and pkmcal fixes three parameters; the referee checks that they are a gauge and compares in it,
and gauge-free (the fitted readings, and the Monte Carlo's prediction errors).
"""

from __future__ import annotations

import numpy as np
import pytest
import referee_gls as rg

N_POSES = 45
N_PLANNED = 60
ERROR_MM = 5.0


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("indicators")
    machine, setup = rg.write_builtins(folder, "stewart-prototype", "indicators-prototype")
    poses = folder / "poses.csv"
    rg.run_pkmcal("plan", machine, "--setup", setup, "--n-poses", N_PLANNED, "--seed", 1, "-o", poses, "--quiet")
    return folder, machine, setup, poses


def campaign(files, seed: int):
    """Campaign ``seed``: (measurements of 45 reached poses, real machine file) or None."""
    folder, machine, setup, poses = files
    return rg.simulate_reached(folder, machine, setup, poses, seed, N_POSES, ERROR_MM)


def test_referee_indicators_against_their_geometry():
    """The referee's indicator model on a pose whose answer is known by hand: the platform
    tilted by b about y through the origin, at height z, touches the indicator at (x_k, y_k)
    where its lower plane, z − d/cos b − x tan b, is (d the plane offset); with a plate lifted
    by h the reading is h lower; the zero is subtracted."""
    sensor = rg.Sensor("indicators", (), None, (), ("d1", "d2"), (False, False), (),
                       positions=np.array([[40.0, 0.0], [-20.0, 30.0]]), plane_offset=10.0)
    b, z, h = 0.05, 300.0, 2.5
    s = np.array([0.1, 0.0, 0.0, 0.0, h, 0.0, 0.0, 0.0])      # zero1, zero2, plate x y z a b c
    got = sensor.predict(np.array([[0.0, 0.0, z, 0.0, b, 0.0]]), s)[0]
    want = z - 10.0 / np.cos(b) - np.array([40.0, -20.0]) * np.tan(b) - h - np.array([0.1, 0.0])
    assert np.allclose(got, want, rtol=0, atol=1e-12)


def test_indicator_campaign_pkmcal_equals_referee(files, tmp_path):
    """One campaign: pkmcal's gauge (three parameters) is one for the referee too, and in it
    pkmcal identify and the referee agree parameter by parameter (39 free)."""
    _, machine, setup, _ = files
    meas, real = campaign(files, 1)
    fit_json = rg.identify(machine, meas, setup, tmp_path / "cal.yaml", "--method", "fk-residual")
    gauge = fit_json["gauge"]
    everything, _ = rg.referee(machine, setup, meas, "fk-residual")
    assert everything.rank()[0] == 42 - len(gauge) == 39, gauge
    ref, fit = rg.referee(machine, setup, meas, "fk-residual", fixed=gauge)
    assert ref.rank()[0] == len(fit.free) == 39
    rg.assert_agree(fit_json, ref, fit, tmp_path / "cal.yaml")
    rg.truth_in_gauge(ref, fit, real, setup)


def test_indicator_monte_carlo_efficiency_and_coverage(files):
    """Over K = :func:`referee_gls.trials_needed` (39) = 46 campaigns: pkmcal's mean squared
    error of the predicted readings is the referee's within 2 % and its reported covariance
    covers them (:class:`referee_gls.PredictionTrials`: the gauge turns the platform frame, so
    the errors are compared where the gauge cannot reach, as for the tracker)."""
    _, machine, setup, _ = files
    rg.prediction_monte_carlo(lambda seed: campaign(files, seed), machine, setup, setup, r=39, first_seed=301)


#: Four indicators on a plate that stands tilted and offset, their zeros not referenced (free).
PLATE_SETUP = """\
sensor: indicators
indicators: [[45, 5], [-25, 35], [-15, -40], [5, 0]]
plane_offset: 12.0
zero: [0.2, -0.1, 0.0, 0.05]
plate: {x: 3.0, y: -2.0, z: 5.0, a: 1.2, b: -0.7, c: 20.0}
free: [zero1, zero2, zero3, zero4]
noise: {distribution: uniform, reading: 0.02, actuator: 0.01}
"""


def test_any_indicator_campaign_pkmcal_equals_referee(files, tmp_path):
    """The referee is not built for paper 2's files: four indicators on a tilted, offset plate
    with unreferenced zeros (free), uniform noise: the same agreement, in pkmcal's gauge,
    which the referee checks."""
    folder, machine, _, poses = files
    setup = tmp_path / "plate.yaml"
    setup.write_text(PLATE_SETUP, encoding="utf-8")
    made = rg.simulate_reached(tmp_path, machine, setup, poses, 7, 30, ERROR_MM)   # 36 of 60 reached
    assert made is not None
    meas, real = made
    fit_json = rg.identify(machine, meas, setup, tmp_path / "cal.yaml", "--method", "fk-residual")
    gauge = fit_json["gauge"]
    everything, _ = rg.referee(machine, setup, meas, "fk-residual")
    assert len(everything.free) == 46 and everything.rank()[0] == 46 - len(gauge), gauge
    ref, fit = rg.referee(machine, setup, meas, "fk-residual", fixed=gauge)
    assert ref.rank()[0] == len(fit.free)
    rg.assert_agree(fit_json, ref, fit, tmp_path / "cal.yaml")
    rg.truth_in_gauge(ref, fit, real, setup)
