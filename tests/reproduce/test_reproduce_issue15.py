"""The reproductions added for issue 15, in quick mode: the claims their notes make hold on
their own numbers, and their figures are drawn.

paper1-table1 (Figs. 10-11, corner box, D-optimal context), paper1-figs4-9 (error maps and
the boundary argument), paper2-table5 (the paper gauge's parameter errors),
paper2-plate-frame, paper2-singularity, paper3-case1/2 (paths, backlash, known stiffness,
Tables 1-2), paper3-compliance (the load trap and the warning).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli

NAMES = ("paper1-table1", "paper1-figs4-9", "paper2-table5", "paper2-plate-frame", "paper2-singularity",
         "paper3-case1", "paper3-case2", "paper3-compliance")


@pytest.fixture(scope="module")
def quick(quick_reproductions):
    assert set(NAMES) <= set(quick_reproductions)
    return quick_reproductions


def _group(r, start):
    return [g for g in dict.fromkeys(row.group for row in r.rows) if g.startswith(start)]


def test_paper1_doptimal_context_and_corner_box(quick):
    r = quick["paper1-table1"]
    groups = _group(r, "stewart-prototype") + _group(r, "machine-tool-hexapod")
    assert len(groups) == 3 and "all-reachable corner box" in groups[1]
    for g in groups:
        ours = {q: r.row(q, g).ours for q in ("after, 15 D-optimal, weighted", "after, 15 boundary, weighted",
                                               "bound on mean |error|, 15 D-optimal",
                                               "bound on mean |error|, 15 boundary",
                                               "corners the real machine reaches (of 64)")}
        assert ours["after, 15 D-optimal, weighted"] < ours["after, 15 boundary, weighted"]
        assert ours["bound on mean |error|, 15 D-optimal"] < ours["bound on mean |error|, 15 boundary"]
        assert 0 < ours["corners the real machine reaches (of 64)"] <= 64
    titles = [t for t, _, _ in r.extra]
    assert sum(t.startswith("Fig. 10") for t in titles) == 2 and sum(t.startswith("Fig. 11") for t in titles) == 2
    fig10 = next(rows for t, _, rows in r.extra if t.startswith("Fig. 10"))
    assert len(fig10) == 43                     # 42 parameters and the mean


def test_reproduction_figures_are_written(quick, tmp_path):
    paths = quick["paper1-table1"].write_figures(tmp_path / "p1", png=False)     # PNG: test_cli_figures_option
    names = sorted(p.name for p in paths)
    assert names == sorted(f"paper1-fig{k}-{m}.svg" for k in (10, 11) for m in ("prototype", "machine-tool"))
    for p in paths:
        if p.suffix == ".svg":
            ET.parse(p)
    from pkmcal.report.figures import render

    spec = quick["paper1-table1"].figures[0]
    assert render(spec.build(), spec.name, spec.caption, png=False).svg == (tmp_path / "p1" / f"{spec.name}.svg").read_bytes()
    p3 = quick["paper3-case1"].write_figures(tmp_path / "p3", png=False)
    assert sorted(p.name for p in p3) == ["paper3-case1-fig4-path.svg", "paper3-case1-fig5-errors.svg"]


def test_paper1_error_maps_are_affine_so_the_count_cannot_fail(quick):
    r = quick["paper1-figs4-9"]
    g = _group(r, "error slices")[0]
    total = r.row("all slices, largest position error at an end", g)
    assert total.ours == float(total.spread.split()[-1])          # every slice peaks at an end
    assert r.row("deviation of the error vector from a straight line (largest slice)", g).ours < 0.05
    g2 = _group(r, "where the information is")[0]
    base = r.row("candidates within 1 mm / 1° of a stroke or joint limit", g2).ours
    assert r.row("D-optimal 30: within 1 mm / 1° of a limit", g2).ours > 1.5 * base


def test_paper2_paper_gauge_parameters_are_far_off(quick):
    r = quick["paper2-table5"]
    g = _group(r, "noise-free")[0]
    assert r.row("largest |θ̂ − θ_real|, paper gauge", g).ours > 10.0
    assert r.row("largest |θ̂ − θ_real|, auto gauge", g).ours < 2.0
    assert r.row("rms residual after fit, paper gauge", g).ours > 0.01


def test_paper2_plate_frame(quick):
    r = quick["paper2-plate-frame"]
    row = lambda q, g: r.row(q, f"noise-free: {g}").ours
    base, plate = "held-out reading error, level centred plate (base frame)", "held-out reading error, the real plate (plate frame)"
    assert row(plate, "parallel frames assumed") < 1e-8 and row(base, "parallel frames assumed") > 1.0
    assert row(base, "plate surveyed") < 1e-8 and row(plate, "plate surveyed") > 1.0
    assert row("plate position error (largest of x, y, z)", "plate free, base surveyed") < 1e-6
    assert row("plate angle error (largest of a, b, c)", "plate free, base surveyed") < 1e-6
    noisy = r.row("reported sd of the plate position (largest)", "indicators sigma 0.01 mm: plate free, base surveyed")
    assert noisy.ours > 0.5                    # identifiable, but weakly determined: the engine says so


def test_paper2_singularity(quick):
    r = quick["paper2-singularity"]
    g = _group(r, "yaw path")[0]
    assert r.row("|det J⁻¹| / L³ at c = 90°", g).ours < 1e-12
    assert r.row("inverse condition number at c = 90°", g).ours < 1e-12
    assert r.row("|det J⁻¹| / L³ at c = 0°", g).ours > 0.1
    g2 = _group(r, "")[-1]
    assert r.row("Spearman rank correlation of the two measures", g2).ours > 0.9


@pytest.mark.parametrize("name", ["paper3-case1", "paper3-case2"])
def test_paper3_paths_backlash_and_known_stiffness(quick, name):
    r = quick[name]
    paths = _group(r, "measurement path")
    g0 = next(g for g in paths if "backlash 0 " in g and g.endswith(": projection"))
    gb = next(g for g in paths if "backlash 0 " not in g and g.endswith(": projection"))
    diff = "|forward − backward| at the same points, after"
    assert r.row(diff, g0).ours == 0.0                  # no backlash: direction does not matter
    assert r.row(diff, gb).ours > 1e-3                  # backlash: it does, after any calibration
    chi2 = lambda g: r.row("reduced χ² of the projection fit", g + " fit").ours
    assert chi2(gb) >= chi2(g0)
    proj = r.row("improvement", "after: projection (projection re-linearised, weighted: our default)").ours
    ks = r.row("improvement", next(g for g in _group(r, "after: known-stiffness (")))
    assert abs(ks.ours - proj) < 3.0                     # K and F known exactly: as good as the projection
    table = next(rows for t, _, rows in r.extra if t.startswith("Paper 3 Table"))
    assert len(table) == len(r.setup["free"].split(", "))


def test_paper3_compliance_trap_and_warning(quick):
    r = quick["paper3-compliance"]
    g = next(g for g in _group(r, "actuators 10x softer"))
    at = lambda where, m: r.row(f"improvement at the {where}: {m}", g).ours
    floor = at("calibration load", "perfect kinematics (the floor)")
    assert floor < 70.0
    assert abs(at("calibration load", "projection") - floor) < 3.0
    assert at("calibration load", "ignore-redundancy") > at("calibration load", "projection") + 10.0   # the trap
    assert at("load removed", "projection") > at("load removed", "ignore-redundancy") + 30.0          # and its cost
    assert at("calibration load", "known-stiffness, load compensated") > floor + 20.0
    assert r.row("report warning given (share of repetitions)", g).ours == 100.0
    est = r.row("deflection estimated from the following errors (max, calibration poses)", g).ours
    true = r.row("true load deflection (max, calibration poses: the floor's errors there)", g).ours
    assert est == pytest.approx(true, rel=0.25)


def test_cli_figures_option(tmp_path):
    res = CliRunner().invoke(cli, ["reproduce", "paper2-singularity", "--quick", "--figures", str(tmp_path / "f")])
    assert res.exit_code == 0 and "draws no figures" in res.output
    res = CliRunner().invoke(cli, ["reproduce", "paper1-figs4-9", "--quick", "--figures", str(tmp_path / "g")])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "g").iterdir()) == ["paper1-figs4-9.png", "paper1-figs4-9.svg"]
    (tmp_path / "file").write_text("x")
    res = CliRunner().invoke(cli, ["reproduce", "paper1-figs4-9", "--quick", "--figures", str(tmp_path / "file")])
    assert res.exit_code == 2


def test_report_warns_of_load_deflection():
    """The calibration report of a projection fit on a soft machine under load carries the
    warning line (pkmcal identify --report builds it the same way)."""
    from pkmcal.identification.simulation import simulate_campaign
    from pkmcal.mechanisms.statics import StaticsModel
    from pkmcal.report.from_results import report_data_from_results
    from pkmcal.reproduce.paper3 import CASES, case_models
    from pkmcal.reproduce.paper3_experiment import fit_redundant
    from pkmcal.sensors.base import MeasurementSetup

    nominal, sensor, noise, real, real_sensor = case_models("paper3-case1")
    cmd = nominal.sample_poses(30, np.random.default_rng(0))
    soft = MeasurementSetup(real_sensor, noise, StaticsModel(CASES["paper3-case1"]["stiffness"] / 10,
                                                             np.array([0.0, -50.0])))
    sim = simulate_campaign(nominal, real, soft, cmd, 1, ("workspace",))
    setup = MeasurementSetup(sensor, noise)
    fit = fit_redundant("projection", nominal, setup, sim.measurements, CASES["paper3-case1"]["free"])
    facts = dict(report_data_from_results(nominal, fit, setup, cmd, commanded=cmd).facts)
    assert "deflected under its load" in facts["warning"]
    assert "warning" not in dict(report_data_from_results(nominal, fit, setup, cmd).facts)   # no commands: none


def test_new_reproductions_report_progress():
    """The new reproductions take the ``progress(done, total)`` callback of the CLI's progress
    bar and end at done == total."""
    from pkmcal.reproduce import paper2_plate_frame, paper2_singularity

    for fn in (paper2_plate_frame, paper2_singularity):
        calls = []
        fn(quick=True, progress=lambda d, t, calls=calls: calls.append((d, t)))
        assert calls and calls[-1][0] == calls[-1][1] and all(d <= t for d, t in calls)
