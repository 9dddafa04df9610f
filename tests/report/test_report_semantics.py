"""What the HTML report states agrees with the command line and says what its numbers count
(issue 10 item 4): the condition number, the identifiability table's header, the headline's
orientation error, pose numbers as the measurement file's data rows (1-based), and why
held-out poses were left out. The page is rendered without figures (render_html with an
empty figure list) so that the checks are on the text."""

from __future__ import annotations

import re

import numpy as np
import pytest

from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.identification.verification import verify
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real
from pkmcal.report.from_results import report_data_from_results
from pkmcal.report.html import render_html
from pkmcal.sensors.library import builtin_setup


def _poses(n, seed):
    rng = np.random.default_rng(seed)
    home = stewart_prototype().home_pose
    return home + rng.uniform(-1, 1, (n, 6)) * np.array([15.0, 15.0, 8.0, *np.deg2rad([4.0, 4.0, 4.0])])


@pytest.fixture(scope="module")
def case():
    """Indicators (a 3-parameter gauge: the report's singular values include ~1e-16 ones),
    two poses whose readings no assembly reproduces (dropped by the fit), held-out poses
    one of which is beyond the stroke."""
    nominal, real = stewart_prototype(), stewart_prototype_real()
    setup = builtin_setup("indicators-prototype")
    sim = simulate_campaign(nominal, real, setup, _poses(40, 0), rng=0, ignore_limits=("leg_collision",))
    meas = sim.measurements
    q = meas.actuators.copy()
    q[[2, 7]] = [400.0, -300.0, 400.0, -300.0, 400.0, -300.0]
    result = identify(nominal, setup, q=q, y=meas.readings, commanded=meas.commanded)
    held = _poses(12, 5)
    held[3, 2] += 300.0
    ver = verify(result.mechanism, real, held, nominal, ignore_limits=("leg_collision",))
    data = report_data_from_results(nominal, result, setup, meas.commanded, verification=ver)
    return result, ver, data, render_html(data, [])


def test_condition_number_is_the_engines(case):
    """Old behaviour: the report took σ_max/σ_min over every positive singular value, the
    null directions (~1e-16) included: 1.364e+16 against the CLI's 2.97e+03."""
    result, _, data, page = case
    cli = result.identifiability.condition_number
    assert not result.identifiability.identifiable          # there is a null space to ignore
    assert data.identifiability.condition_number == pytest.approx(cli, rel=1e-12)
    assert cli < 1e8
    assert f">{cli:.4g}</td>" in page


def test_identifiability_table_has_a_header(case):
    """Old behaviour: an empty header row (two empty <th>)."""
    page = case[3]
    section = page.split('id="identifiability"')[1].split("<h2")[0]
    header = re.search(r"<table>\n<tr>(.*?)</tr>", section).group(1)
    assert re.sub(r"<[^>]+>", "", header).strip() != ""
    assert "Jacobian evaluated at" in section and "commanded poses" in section


def test_headline_states_orientation_and_left_out_poses(case):
    """Old behaviour: the headline showed the position error only, and not that a held-out
    pose had been left out."""
    _, ver, data, page = case
    head = re.search(r'<p class="headline">(.*?)</p>', page).group(1)
    h = data.held_out
    ob, oa = (np.sqrt(np.mean(e**2)) * np.rad2deg(1.0) * 3600 for e in (h.orientation_before, h.orientation_after))
    assert f"Orientation error (rms): {ob:.1f}″ before → {oa:.2f}″ after" in head
    assert f"{h.n_poses} poses not used for identification of 12 given (1 left out, see Verification)" in head
    dropped = {k + 1 for k in ver.dropped}
    assert dropped == {4}
    verification = page.split('id="verification"')[1]
    assert "<td class=\"l\">4</td>" in verification and "real-limits" in verification


def test_pose_numbers_are_rows_of_the_measurement_file(case):
    """Old behaviour: 'Poses with the largest residuals' counted the fitted poses from 1, so
    after dropped poses the numbers pointed at the wrong rows."""
    result, _, data, page = case
    assert list(result.dropped) == [2, 7]
    assert np.array_equal(data.residuals.pose_numbers, result.used_poses + 1)
    r = result.residuals / 0.01                      # all rows are indicator readings (mm)
    worst = result.used_poses[np.argsort(-np.sqrt(np.mean(r**2, axis=1)), kind="stable")[:3]] + 1
    text = re.search(r"Poses with the largest residuals: ([\d, ]+) \(pose numbers: data rows", page).group(1)
    assert [int(v) for v in text.split(", ")] == worst.tolist()
    assert "poses used" in page and "rows 3, 8 of the measurement file" in page
