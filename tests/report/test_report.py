"""The HTML calibration report: self-contained, deterministic, faithful to its input.

The input is a small but genuine calibration, computed here without the engine: the leg
offsets and platform joints of ``stewart-prototype`` are fitted by Gauss–Newton to the
simulated leg readings of ``stewart-prototype-real`` at full-pose measured poses
(paper 1's ik-residual model r = q − IK(x, ρ)).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from pkmcal.conventions import euler_to_matrix, rotation_error
from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real
from pkmcal.report import (
    ErrorMap,
    HeldOutErrors,
    Identifiability,
    ParameterTable,
    ReportData,
    Residuals,
    correlation_from_covariance,
    write_report,
)
from pkmcal.report.data import summarise
from pkmcal.report.html import inline_svg

SPAN = np.array([20.0, 20.0, 10.0, 0.08, 0.08, 0.08])


def _commanded_errors(real, model, targets):
    """Position (mm) and orientation (rad) error of ``real`` commanded by ``model``."""
    reached = real.fk(model.ik(targets), targets).poses
    pos = np.linalg.norm(reached[:, :3] - targets[:, :3], axis=1)
    ori = rotation_error(euler_to_matrix(reached[:, 3:]), euler_to_matrix(targets[:, 3:]))
    return pos, ori


def make_report_data(n_poses: int = 24, seed: int = 3, rank_deficient: bool = False) -> ReportData:
    nominal, real = stewart_prototype(), stewart_prototype_real()
    rng = np.random.default_rng(seed)
    poses = nominal.home + rng.uniform(-1, 1, (3 * n_poses, 6)) * SPAN
    poses = poses[real.check_limits(poses).ok][:n_poses]
    q = real.ik(poses) + rng.normal(0.0, 0.002, (len(poses), 6))
    free_names = tuple(n for n in nominal.param_names if n.startswith(("a", "L0")))
    free = np.isin(nominal.param_names, free_names)
    rho = nominal.params.copy()
    for _ in range(6):
        J = nominal.with_params(rho).actuator_param_jacobian(poses).reshape(-1, free.size)[:, free]
        r = (q - nominal.with_params(rho).ik(poses)).ravel()
        rho[free] += np.linalg.lstsq(J, r, rcond=None)[0]
    identified = nominal.with_params(rho, name="stewart-prototype-identified")
    res = q - identified.ik(poses)
    J = identified.actuator_param_jacobian(poses).reshape(-1, free.size)[:, free]
    sigma2 = np.sum(res**2) / (res.size - free.sum())
    cov_free = sigma2 * np.linalg.inv(J.T @ J)
    std = np.full(free.size, np.nan)
    std[free] = np.sqrt(np.diag(cov_free))
    s = np.linalg.svd(J / np.linalg.norm(J, axis=0), compute_uv=False)
    rank = int(free.sum()) - (2 if rank_deficient else 0)
    held = nominal.home + rng.uniform(-1, 1, (20, 6)) * SPAN
    pb, ob = _commanded_errors(real, nominal, held)
    pa, oa = _commanded_errors(real, identified, held)
    x = nominal.home[0] + np.linspace(-20, 20, 7)
    y = nominal.home[1] + np.linspace(-20, 20, 6)
    grid = np.array([[xx, yy, nominal.home[2], 0, 0, 0] for yy in y for xx in x])
    eb = _commanded_errors(real, nominal, grid)[0].reshape(6, 7)
    ea = _commanded_errors(real, identified, grid)[0].reshape(6, 7)
    return ReportData(
        title="pkmcal test report",
        machine_summary=nominal.summary(),
        nominal=nominal,
        identified=identified,
        poses=poses,
        identifiability=Identifiability(
            rank=rank, n_params=int(free.sum()), singular_values=s,
            fixed=tuple(n for n in nominal.param_names if n not in free_names),
            weak=("a1.z (σ/σ₁ = 3e-5)",), null_space=("L0_1 + a1.z",) if rank_deficient else (),
        ),
        parameters=ParameterTable(nominal.param_names, nominal.params, rho, std, free, true=real.params),
        correlation=correlation_from_covariance(cov_free),
        correlation_names=free_names,
        residuals=Residuals(res, nominal.actuator_names, ("mm",) * 6),
        held_out=HeldOutErrors(pb, pa, ob, oa),
        error_map=ErrorMap(x, y, float(nominal.home[2]), eb, ea),
        setup_summary="full pose, leg noise 0.002 mm",
        facts=(("seed", str(seed)), ("method", "ik-residual (test)")),
        held_out_poses=held,
    )


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    data = make_report_data()
    out = tmp_path_factory.mktemp("report")
    files = write_report(data, out)
    return data, files, files.html.read_text(encoding="utf-8")


def test_report_writes_page_and_figure_files(report):
    data, files, page = report
    names = {p.stem for p in files.figures}
    assert names == {"machine-poses", "pose-cloud", "singular-values", "parameters", "parameter-errors", "correlation",
                     "residuals-per-pose", "residuals-per-reading", "held-out", "held-out-per-pose", "error-map"}
    for p in files.figures:
        assert p.exists() and p.stat().st_size > 1000
        assert p.parent == files.html.parent
    for p in files.figures:
        if p.suffix == ".svg":
            ET.parse(p)  # well-formed XML
        else:
            assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for name in names:
        block = re.search(rf'<figure id="fig-{name}">(.*?)</figure>', page, re.S)
        assert block is not None and "<svg " in block.group(1)


def test_report_is_self_contained(report):
    _, _, page = report
    lowered = page.lower()
    assert "<script" not in lowered and "<link" not in lowered and "@import" not in lowered
    assert "<img" not in lowered  # every figure is inline
    # The only URLs allowed are XML namespace names, which are never fetched.
    urls = set(re.findall(r'(?:src|href)\s*=\s*"([^"#][^"]*)"', page))
    assert all(u.startswith("data:image/png;base64,") for u in urls)  # images inside the SVGs
    assert set(re.findall(r"https?://[^\s\"')]+", page)) <= {
        "http://www.w3.org/2000/svg", "http://www.w3.org/1999/xlink", "http://purl.org/dc/elements/1.1/",
        "http://creativecommons.org/ns#", "http://www.w3.org/1999/02/22-rdf-syntax-ns#",
        "http://purl.org/dc/dcmitype/StillImage",
    }


def test_inline_svg_ids_are_unique_and_references_resolve(report):
    _, _, page = report
    ids = re.findall(r'\bid="([^"]+)"', page)
    assert len(ids) == len(set(ids))
    refs = set(re.findall(r'href="#([^"]+)"', page)) | set(re.findall(r"url\(#([^)]+)\)", page))
    assert refs and refs <= set(ids)


def test_inline_svg_prefixes_ids():
    svg = (b'<?xml version="1.0"?>\n<svg xmlns="http://www.w3.org/2000/svg" width="1pt"><defs>'
           b'<path id="a1"/></defs><use xlink:href="#a1"/><g clip-path="url(#a1)"/></svg>')
    out = inline_svg(svg, "fig")
    assert out.startswith("<svg ")
    twice = inline_svg(svg.replace(b"<use", b"<image id=\"a1\"/><use"), "f")
    assert twice.count('id="f-a1"') == 1 and 'id="f-a1-2"' in twice
    assert 'id="fig-a1"' in out and 'href="#fig-a1"' in out and "url(#fig-a1)" in out
    assert 'id="a1"' not in out


def test_report_is_byte_identical_on_rerun(report, tmp_path):
    _, a, _ = report
    b = write_report(make_report_data(), tmp_path / "b")
    assert [p.name for p in a.figures] == [p.name for p in b.figures]
    for pa, pb in zip(a.figures + (a.html,), b.figures + (b.html,)):
        assert pa.read_bytes() == pb.read_bytes(), pa.name


def test_report_numbers_match_input(report):
    data, _, page = report
    h = data.held_out
    rms_before = np.sqrt(np.mean(h.position_before**2)) * 1000
    rms_after = np.sqrt(np.mean(h.position_after**2)) * 1000
    assert f"{rms_before:.1f} µm before → {rms_after:.2f} µm after" in page
    assert rms_after < rms_before / 5  # the fitted machine is genuinely better
    t = data.parameters
    for i in (0, 6, 41):
        assert f"<td>{t.identified[i]:.4f}</td>" in page
    assert page.count("<tr class=\"fixed\">") == int((~t.free).sum())
    assert f"crosses: the {len(data.held_out_poses)} held-out poses" in page
    assert f"{data.identifiability.rank} of {data.identifiability.n_params} candidate parameters" in page


def test_rank_deficiency_is_flagged(tmp_path):
    data = make_report_data(n_poses=12, rank_deficient=True)
    page = write_report(data, tmp_path, png=False).html.read_text(encoding="utf-8")
    assert 'class="warn"' in page and "L0_1 + a1.z" in page
    assert not list(tmp_path.glob("*.png"))


def test_summaries_closed_form():
    s = summarise(np.array([3.0, 4.0]))
    assert s["rms"] == pytest.approx(np.sqrt(12.5)) and s["max"] == 4.0 and s["mean"] == 3.5
    cov = np.array([[4.0, 2.0, 0.0], [2.0, 9.0, 0.0], [0.0, 0.0, 0.0]])
    c = correlation_from_covariance(cov)
    assert c[0, 1] == pytest.approx(2.0 / 6.0) and c[0, 0] == pytest.approx(1.0)
    assert c[2, 2] == 0.0 and c[0, 2] == 0.0 and c[2, 0] == 0.0   # zero variance: row stays zero


def test_report_input_is_validated():
    with pytest.raises(PkmcalError, match="identified"):
        ParameterTable(("p1", "p2"), [0, 0], [0, 0, 0], [0, 0], [True, True])
    with pytest.raises(PkmcalError, match="units"):
        Residuals(np.zeros((3, 2)), ("d1", "d2"), ("mm", "deg"))
    with pytest.raises(PkmcalError, match="expected"):
        HeldOutErrors([1.0, 2.0], [1.0], [0.0, 0.0], [0.0, 0.0])
    with pytest.raises(PkmcalError, match="error map"):
        ErrorMap([0, 1], [0, 1, 2], 0.0, np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(PkmcalError, match="unknown identifiability keys"):
        Identifiability.from_mapping({"rank": 1, "n_params": 1, "singular_values": [1.0], "colour": 2})


def test_report_refuses_a_file_as_folder(tmp_path):
    f = tmp_path / "taken"
    f.write_text("x")
    with pytest.raises(PkmcalError, match="not a folder"):
        write_report(make_report_data(n_poses=12), f)


def test_report_from_an_engine_result_without_verification(tmp_path):
    """What ``pkmcal identify --report`` writes: paper 2's indicators, fk-residual, the
    engine's automatic gauge, no held-out poses."""
    from pkmcal.identification.engine import identify
    from pkmcal.identification.simulation import simulate_campaign
    from pkmcal.io.setup_file import builtin_setup
    from pkmcal.planning.candidates import generate_candidates
    from pkmcal.report.from_results import report_data_from_results

    nominal, real = stewart_prototype(), stewart_prototype_real()
    setup = builtin_setup("indicators-prototype")
    poses = generate_candidates(nominal, setup, kind="random", n=60, rng=np.random.default_rng(4)).poses
    sim = simulate_campaign(nominal, real, setup, poses, rng=5)
    result = identify(nominal, setup, sim.measurements, method="fk-residual")
    data = report_data_from_results(nominal, result, setup, sim.commanded[sim.kept])
    assert data.residuals.names == ("d1", "d2", "d3") and data.residuals.units == ("mm",) * 3
    assert data.identifiability.rank < data.identifiability.n_params  # indicators see 39 of 42
    assert set(result.gauge) <= set(data.identifiability.fixed)
    assert data.parameters.free.sum() == len(result.free)
    page = write_report(data, tmp_path, png=False).html.read_text(encoding="utf-8")
    assert "No held-out poses were given." in page and 'class="warn"' in page
    for name in result.gauge:
        assert f'<tr class="fixed"><td class="l">{name}</td>' in page
    rms = np.sqrt(np.mean(result.residuals[:, 0] ** 2)) * 1000
    assert f"<td>{rms:.3f}</td>" in page


# -- planar machines: angle parameters in degrees, by the declared flags -------------------


def _planar_identification(name: str):
    """A projection fit (paper 3) of a planar machine whose every parameter is off (angles by
    0.05°, lengths by 0.1 mm), with the tracker frame (world.x, world.y, world.c) free."""
    import dataclasses

    from pkmcal.identification.engine import identify
    from pkmcal.identification.simulation import simulate_campaign
    from pkmcal.io.setup_file import builtin_setup
    from pkmcal.mechanisms.library import builtin_machine

    nominal = builtin_machine(name)
    errors = {n: (np.deg2rad(0.05) if a else 0.1) * (-1) ** k
              for k, (n, a) in enumerate(zip(nominal.param_names, nominal.param_is_angle))}
    real = nominal.with_deltas(errors)
    setup = builtin_setup("planar-tracker", nominal)
    sensor = dataclasses.replace(setup.sensor, free=("target.x", "target.y", "world.x", "world.y", "world.c"))
    setup = dataclasses.replace(setup, sensor=sensor)
    real_sensor = sensor.with_params(np.array([0.5, -0.2, 1.0, 2.0, np.deg2rad(0.3)]))
    poses = nominal.sample_poses(20, np.random.default_rng(1))
    sim = simulate_campaign(nominal, real, dataclasses.replace(setup, sensor=real_sensor), poses,
                            np.random.default_rng(2))
    result = identify(nominal, setup, sim.measurements, method="projection")
    assert result.success
    return nominal, real, real_sensor, setup, sim, result


def _parameter_cells(page: str) -> dict[str, list[str]]:
    """{name: [unit, nominal, identified, deviation, σ, true, error]} of the parameters table."""
    section = page[page.index('<h2 id="parameters">'):page.index('<h2 id="residuals">')]
    table = section[section.index("<table>"):section.index("</table>")]
    rows = re.findall(r"<tr(?: class=\"fixed\")?>(.*?)</tr>", table)
    cells = [re.findall(r"<t[dh][^>]*>(.*?)</t[dh]>", r) for r in rows]
    assert cells[0][:6] == ["parameter", "unit", "nominal", "identified", "deviation", "± 1σ"]
    return {c[0]: c[1:] for c in cells[1:]}


@pytest.mark.parametrize("name, angles", [("planar-2dof-3act", {"dq1", "dq2", "dq3", "world.c"}),
                                          ("planar-3dof-4act", {"alpha1", "alpha2", "world.c"})])
def test_planar_report_shows_angle_parameters_in_degrees(tmp_path, name, angles):
    """Angle parameters (way directions alpha*, rotary encoder offsets dq* of the 2-dof machine,
    the tracker's world.c) in degrees with unit "deg", lengths (the 3-dof machine's linear dq*
    too) in mm; every number against the engine's radians converted here independently."""
    from pkmcal.report.from_results import report_data_from_results

    nominal, real, real_sensor, setup, sim, result = _planar_identification(name)
    data = report_data_from_results(nominal, result, setup, sim.commanded[sim.kept], true_machine=real,
                                    true_sensor=real_sensor)
    t = data.parameters
    assert {n for n, a in zip(t.names, t.is_angle) if a} == angles
    cells = _parameter_cells(write_report(data, tmp_path, png=False).html.read_text(encoding="utf-8"))
    free_std = dict(zip(result.free, result.std))
    truth = dict(zip(nominal.param_names + real_sensor.param_names,
                     np.r_[real.params, real_sensor.params]))
    shown = [n for n in result.names if n in nominal.param_names or n in result.free or n in result.gauge]
    assert list(cells) == shown
    for n in shown:
        i = result.names.index(n)
        a = n in angles
        scale = 180.0 / np.pi if a else 1.0
        d = 6 if a else 4
        unit, nom, ident, dev, sd, true, err = cells[n]
        assert unit == ("deg" if a else "mm"), n
        assert nom == f"{result.initial[i] * scale:.{d}f}" and ident == f"{result.estimate[i] * scale:.{d}f}", n
        assert dev == f"{(result.estimate[i] - result.initial[i]) * scale:+.{d}f}", n
        assert sd == (f"{free_std[n] * scale:.{d}f}" if n in free_std else "fixed"), n
        assert true == f"{truth[n] * scale:.{d}f}", n
        assert err == f"{(result.estimate[i] - truth[n]) * scale * (3600.0 if a else 1000.0):+.2f}", n
    # the page really is in degrees: an angle's radian value does not appear, its degrees do;
    # shown on the free angle of largest estimate (world.c, 0.3° true), chosen by value, never by
    # the iteration order of a set
    est = {n: result.estimate[result.names.index(n)] for n in sorted(angles) if n in free_std}
    k = max(est, key=lambda n: abs(est[n]))
    assert abs(np.rad2deg(est[k])) > 0.1 and cells[k][2] != f"{est[k]:.6f}"
    # the projection's residual rows are whitened combinations of readings (weighted fit)
    assert data.residuals.units == ("1",) * len(result.residual_names)


def test_residual_units_follow_the_declared_reading_flags():
    """Rows named after readings take the reading's declared unit; the projection's rows are
    "1" when whitened or mixing mm and rad, else the readings' common unit."""
    from pkmcal.io.setup_file import builtin_setup
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.report.from_results import residual_units

    rotary, linear = builtin_machine("planar-2dof-3act"), builtin_machine("planar-3dof-4act")
    s_rot, s_lin = builtin_setup("planar-tracker", rotary), builtin_setup("planar-tracker", linear)
    assert residual_units(("px", "q1", "r1"), s_rot, rotary) == ("mm", "rad", "1")        # tracker mm, encoders rad
    assert residual_units(("px", "q1", "r1"), s_lin, linear) == ("mm", "mm", "mm")
    assert residual_units(("r1",), s_lin, linear, weighted=True) == ("1",)
    full = builtin_setup("full-pose-paper1")
    hexapod = stewart_prototype()
    assert residual_units(("x", "c", hexapod.actuator_names[0]), full, hexapod) == ("mm", "rad", "mm")


def test_pose_points_read_the_pose_coordinates_by_name():
    """Positions, tilt arccos(cos a cos b) (R₃₃ of Rz Ry Rx) and yaw of a hexapod's poses;
    a delta's positions without tilt; a pose pair's second point; none for a planar machine."""
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.mechanisms.pose_pairs import PosePairs
    from pkmcal.report.data import pose_points

    hexapod = stewart_prototype()
    poses = np.array([[1.0, 2.0, 3.0, 0.1, -0.2, 0.3], [0.0, 0.0, 0.0, 0.0, 0.0, -1.0]])
    shown = pose_points(hexapod, poses)
    np.testing.assert_array_equal(shown.points, poses[:, :3])
    tilt = [np.arccos(euler_to_matrix(p[3:])[2, 2]) for p in poses]
    np.testing.assert_allclose(shown.tilt, tilt, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(shown.yaw, poses[:, 5])
    assert shown.second is None

    delta = builtin_machine("kossel-mini")
    single = pose_points(delta, poses[:, :3])
    assert single.tilt is None and single.yaw is None and single.second is None
    pairs = pose_points(PosePairs(delta), poses)        # (x, y, z, x_2, y_2, z_2)
    np.testing.assert_array_equal(pairs.points, poses[:, :3])
    np.testing.assert_array_equal(pairs.second, poses[:, 3:])
    assert pairs.tilt is None                           # x_2, y_2 are not roll and pitch
    assert pose_points(builtin_machine("planar-3dof-4act"), np.zeros((2, 3))) is None


def test_report_of_printed_distances_draws_pairs_not_tilts(tmp_path):
    """identify --report on Klipper's DELTA_ANALYZE pairs: the plan line gives the points'
    extent with no tilt or yaw (a pair's second point is not an angle), the pose cloud
    draws the 7 probe points and the 12 pairs."""
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    log = Path(__file__).resolve().parents[2] / "examples" / "klipper" / "delta-analyze.log"
    run = CliRunner()
    pairs = tmp_path / "pairs.csv"
    res = run.invoke(cli, ["import", "klipper-analyze", str(log), "--machine", "kossel-mini", "--object-machine",
                           "kossel-mini", "-o", str(pairs)])   # the example's object: printed with the probe's config
    assert res.exit_code == 0, res.output
    res = run.invoke(cli, ["identify", "kossel-mini", str(pairs), "--setup", "printed-distance-klipper",
                           "-o", str(tmp_path / "cal.yaml"), "--report", str(tmp_path / "rep")])
    assert res.exit_code == 0, res.output
    page = (tmp_path / "rep" / "report.html").read_text()
    line = re.search(r"<p>19 poses; x [^<]*</p>", page).group(0)
    assert "tilt" not in line and "yaw" not in line
    assert "probe points, and the pairs of points whose distance was measured" in page
    svg = (tmp_path / "rep" / "pose-cloud.svg").read_text()
    assert "probe points (7)" in svg and "distance pairs (12)" in svg and "platform tilt" not in svg
