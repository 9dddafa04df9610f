"""The report opens with what was achieved and what to do next, and draws before and after in
one colour each, with compared maps on one colour scale (issue 27 item 4).

The campaign is tests/test_report.py's small but genuine calibration (stewart-prototype's
leg offsets and platform joints fitted to simulated readings of stewart-prototype-real); the
figures are inspected at the matplotlib level (their artists), not as pixels.
"""

from __future__ import annotations

import re
from dataclasses import replace
from types import SimpleNamespace

import matplotlib.colors as mcolors
import numpy as np
import pytest
from test_report import make_report_data

from pkmcal.conventions import angle_text, length_text
from pkmcal.mechanisms.library import builtin_machine
from pkmcal.report import figures as F
from pkmcal.report import write_report
from pkmcal.report.html import achieved, export_command, next_steps


@pytest.fixture(scope="module")
def data():
    return replace(make_report_data(), calibrated_file="cal.yaml", setup_name="full-pose-paper1")


@pytest.fixture(scope="module")
def page(data, tmp_path_factory):
    return write_report(data, tmp_path_factory.mktemp("opening"), png=False).html.read_text(encoding="utf-8")


def _section(page: str) -> str:
    return re.search(r'<section id="summary">(.*?)</section>', page, flags=re.S).group(1)


def test_the_report_opens_with_before_and_after_in_peoples_units(data, page):
    # the opening section comes first: before the navigation and every other section
    assert page.index('<section id="summary">') < page.index("<nav>") < page.index('id="machine"')
    opening = _section(page)
    s = data.held_out.summary()
    pb, pa = s["position_before"]["rms"], s["position_after"]["rms"]
    ob, oa = s["orientation_before"]["rms"], s["orientation_after"]["rms"]
    # independent of the code under test: the rms of the per-pose errors and the unit rules
    # (µm below 0.1 mm, arcseconds below 0.01°)
    assert pb == pytest.approx(np.sqrt(np.mean(data.held_out.position_before ** 2)), rel=1e-12)
    assert f"position error, rms: {length_text(pb)} → {length_text(pa)}" in opening
    assert f"orientation error, rms: {angle_text(ob)} → {angle_text(oa)}" in opening
    assert f"({pb / pa:.3g}× smaller)" in opening
    assert "e-0" not in opening and "np.float64" not in opening
    assert f"Over {data.held_out.n_poses} held-out poses against the true machine" in opening
    assert f"<span style=\"color:{F.BEFORE_COLOUR}\">before</span>" in opening


def test_what_to_do_next_names_the_export_and_what_to_measure(page):
    opening = _section(page)
    assert "pkmcal export cal.yaml --format linuxcnc -o kinematics.hal --ini joints.ini" in opening
    # full rank with a weak direction: what is weak, and the command that ranks what to add
    assert "a1.z (σ/σ₁ = 3e-5)" in opening
    assert ("pkmcal identifiability stewart-prototype --setup full-pose-paper1 --poses POSES.csv --suggest"
            in opening)
    # a rank-deficient fit names what the data do not see
    deficient = replace(make_report_data(rank_deficient=True), calibrated_file="cal.yaml")
    steps = next_steps(deficient)
    assert "do not see (L0_1 + a1.z)" in steps[1][0] and steps[1][1].endswith("--setup SETUP --poses POSES.csv --suggest")


def test_the_export_command_is_the_machines_controllers():
    for name, fmt in (("stewart-prototype", "--format linuxcnc -o kinematics.hal"),
                      ("kossel-mini", "--format klipper -o printer-calibrated.cfg"),
                      ("delta-picker", "--format klipper"), ("servo-stewart", "--format json")):
        got = export_command(SimpleNamespace(identified=builtin_machine(name), calibrated_file="k.yaml"))
        assert got.startswith("pkmcal export k.yaml ") and fmt in got, (name, got)
    assert export_command(SimpleNamespace(identified=builtin_machine("kossel-mini"), calibrated_file=None)).startswith(
        "pkmcal export CALIBRATED.yaml ")


def test_without_held_out_data_the_opening_says_so_and_what_to_measure(data, tmp_path):
    bare = replace(data, held_out=None, error_map=None, held_out_poses=None)
    assert achieved(bare) == []
    opening = _section(write_report(bare, tmp_path, png=False).html.read_text(encoding="utf-8"))
    assert "No held-out data" in opening and "pkmcal verify cal.yaml --held-out HELDOUT.csv" in opening


def test_measured_held_out_data_give_before_and_after():
    """identify --heldout's validation (HeldoutReport.to_dict with its rows), in mm and deg."""
    v = {"measurements": "held.csv", "n_poses": 12, "n_poses_file": 12,
         "before": {"position_rms_mm": 0.8123, "position_max_mm": 1.5, "orientation_rms_deg": 0.05},
         "after": {"position_rms_mm": 0.01234, "position_max_mm": 0.03, "orientation_rms_deg": 0.002},
         "rows": [("position mean", "mm", "position_mean_mm"), ("position rms", "mm", "position_rms_mm"),
                  ("position max", "mm", "position_max_mm"), ("orientation rms", "deg", "orientation_rms_deg")]}
    base = make_report_data()
    got = achieved(replace(base, held_out=None, measured_validation=v))
    texts = [a.text() for a in got]
    assert texts[0] == "position error, rms: 0.8123 mm → 12.34 µm (65.8× smaller)"
    assert texts[1].startswith("position error, largest: 1.500 mm → 30.00 µm")
    assert texts[2].startswith("orientation error, rms: 0.05000° → 7.200″")
    assert all(a.n == 12 and "held.csv" in a.source for a in got)
    # a sensor that reads no position (dial indicators): its reading residuals
    v = {**v, "before": {"reading_rms_mm": 0.05}, "after": {"reading_rms_mm": 0.004},
         "rows": [("reading residual rms", "mm", "reading_rms_mm")]}
    assert [a.text() for a in achieved(replace(base, held_out=None, measured_validation=v))] == [
        "reading residual, rms: 50.00 µm → 4.000 µm (12.5× smaller)"]


# -- colours: one for before, one for after, in every figure ---------------------------------

def _colour(artist) -> str | None:
    """The colour of a line, collection or patch as #rrggbb (its edge for open markers)."""
    for get in ("get_color", "get_facecolor", "get_edgecolor", "get_markeredgecolor"):
        if hasattr(artist, get):
            c = getattr(artist, get)()
            c = np.asarray(c)
            if c.dtype.kind in "US":
                return mcolors.to_hex(str(c))
            c = c.reshape(-1, 4)[0] if c.size >= 4 else c
            if c.size in (3, 4):
                return mcolors.to_hex(c[:3])
    return None


def _series(fig):
    """(label, colour) of every labelled line, collection and patch of ``fig``."""
    out = []
    for ax in fig.axes:
        for artist in [*ax.lines, *ax.collections, *ax.patches]:
            label = artist.get_label()
            if label and not label.startswith("_"):
                out.append((label, _colour(artist), artist))
    return out


def _check_roles(fig, name):
    """Every series labelled before… is BEFORE_COLOUR, every after… AFTER_COLOUR, and no other
    series or unlabelled artist uses either colour."""
    roles = {F.BEFORE_COLOUR: "before", F.AFTER_COLOUR: "after"}
    seen = set()
    for label, colour, _ in _series(fig):
        low = label.lower()
        role = "before" if low.startswith("before") else "after" if low.startswith("after") else None
        if role is not None:
            assert colour == (F.BEFORE_COLOUR if role == "before" else F.AFTER_COLOUR), (name, label, colour)
            seen.add(role)
        else:
            assert colour not in roles, (name, label, colour)
    for ax in fig.axes:
        for artist in [*ax.lines, *ax.collections]:
            label = artist.get_label()
            if _colour(artist) in roles and (not label or label.startswith("_")):
                pytest.fail(f"{name}: an unlabelled artist in the {roles[_colour(artist)]} colour")
    return seen


def test_every_figure_of_the_report_draws_before_and_after_in_their_colours(data, monkeypatch, tmp_path):
    figs = {}
    render = F.render

    def capture(fig, name, *args, **kw):
        figs[name] = fig
        return render(fig, name, *args, **kw)

    monkeypatch.setattr(F, "render", capture)
    write_report(data, tmp_path, png=False)
    assert {"held-out", "held-out-per-pose", "parameter-errors", "error-map", "parameters"} <= set(figs)
    both = {name: _check_roles(fig, name) for name, fig in figs.items()}
    # the figures that compare before and after show both, each in its colour
    for name in ("held-out", "held-out-per-pose", "parameter-errors"):
        assert both[name] == {"before", "after"}, name
    # the error maps: titles in the two colours
    titles = {ax.get_title(): ax.title.get_color() for ax in figs["error-map"].axes if ax.get_title()}
    assert mcolors.to_hex(titles["before (nominal)"]) == F.BEFORE_COLOUR
    assert mcolors.to_hex(titles["after (identified)"]) == F.AFTER_COLOUR


def test_the_paper_figures_draw_before_and_after_in_their_colours():
    rng = np.random.default_rng(1)
    path = F.path_errors_figure(rng.random(12), {"projection": rng.random(12), "ignore-redundancy": rng.random(12)},
                                rng.random(12) > 0.5)
    assert _check_roles(path, "path-errors") == {"before", "after"}
    points = F.path_figure(rng.random((12, 2)), rng.random(12) > 0.5, rng.random(12) > 0.3)
    assert _check_roles(points, "path") == set()          # calibration/verification: neither colour
    e = {"before (nominal)": rng.random(8), "after (identified)": rng.random(8)}
    assert _check_roles(F.per_pose_errors_figure(e, e), "per-pose") == {"before", "after"}


def test_compared_error_maps_share_one_colour_scale(data):
    fig = F.error_map_figure(data.error_map)
    images = [im for ax in fig.axes for im in ax.images]
    assert len(images) == 2
    (lo1, hi1), (lo2, hi2) = ((im.norm.vmin, im.norm.vmax) for im in images)
    assert (lo1, hi1) == (lo2, hi2)
    # the scale spans both maps: from the smallest positive error of either to the largest (µm)
    both = np.concatenate([data.error_map.before.ravel(), data.error_map.after.ravel()]) * 1000.0
    assert lo1 == pytest.approx(both[both > 0].min(), rel=1e-12) and hi1 == pytest.approx(both.max(), rel=1e-12)
    # after is far below before here, so the maps' own ranges differ: a shared scale is not theirs
    assert data.error_map.after.max() * 1000.0 < 0.5 * hi1
    # one colour bar for both
    assert sum(1 for ax in fig.axes if ax.get_ylabel().startswith("position error (µm), one scale")) == 1
