"""A delta printer's default path (issue 25 items 1-2): what a fit frees from what its sensor
sees, what it says it does not know, and an export that never writes a confident wrong
config.

On the tutorial's printer (docs/tutorial-files/delta: a simulated Kossel probed at 37 points,
its true rods 215.12/214.93/215.06 mm, rail b leaning 0.15°):

* the default free set: a Z probe (heights only, on the bed) holds the arms and the rail
  leans, a prior on the arms frees them, ``--free`` names any; the printed object (lengths,
  on the bed) holds only the leans; a laser tracker nothing;
* identify warns of the common scale of arms and radius the heights leave undetermined (σ
  1.5 %), records it, and export repeats it and writes it as comments; with the rods
  measured (a prior) there is nothing to say;
* the firmware numbers' standard deviations (io/delta_firmware.firmware_sigmas) against a
  Monte Carlo of the covariance, and equal under two gauges of the same fit;
* export refuses a firmware number with σ beyond tolerance unless accepted by name, refits
  by default only on the unchanged measurement file the record names, and a refit with no
  residual to spare is an error.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.firmware_refit import firmware_refit
from pkmcal.identification.priors import Prior
from pkmcal.identification.residuals import sensor_held_parameters
from pkmcal.io.delta_firmware import FIRMWARE_NUMBERS, exact_rewrite, firmware_sigmas
from pkmcal.io.machine_file import load_machine
from pkmcal.io.measurements import Measurements, load_measurements
from pkmcal.io.setup_file import load_setup

FILES = Path(__file__).resolve().parents[2] / "docs" / "tutorial-files" / "delta"
ARMS = ("arm_a", "arm_b", "arm_c")
LEANS = tuple(f"lean_{k}_{t}" for k in ("radial", "tangential") for t in "abc")
#: the machine's parameter order (per tower: radial, tangential)
LEANS_ORDER = (lambda n: (n[-1], "tangential" in n))


@pytest.fixture(scope="module")
def printer(tmp_path_factory):
    """The tutorial's files imported: delta.yaml and probe.csv in a work folder."""
    work = tmp_path_factory.mktemp("delta")
    for name in ("printer.cfg", "probe.log", "check.log"):
        shutil.copy(FILES / name, work / name)
    run = CliRunner()
    for args in (["import", "klipper", "printer.cfg", "--name", "my-kossel", "-o", "delta.yaml"],
                 ["import", "klipper-probe", "probe.log", "--machine", "delta.yaml", "-o", "probe.csv"]):
        res = _invoke(run, work, args)
        assert res.exit_code == 0, res.output
    return work


def _invoke(runner, work, args):
    import os

    old = os.getcwd()
    os.chdir(work)
    try:
        return runner.invoke(cli, args)
    finally:
        os.chdir(old)


def _fit(work, free=None, fix=None, priors=()):
    nominal = load_machine(str(work / "delta.yaml"))
    setup = load_setup("z-probe-klipper", nominal)
    meas = load_measurements(str(work / "probe.csv"), nominal, setup)
    return nominal, setup, meas, identify(nominal, setup, meas, free=free, fix=fix, priors=priors)


def test_a_z_probe_fit_holds_the_arms_and_leans_unless_freed_or_measured(printer):
    nominal, setup, meas, fit = _fit(printer)
    assert not set(ARMS + LEANS) & set(fit.free)
    assert set(fit.free) == {"radius_b", "radius_c", "angle_c", "endstop_a", "endstop_b", "endstop_c"}
    # rods measured with calipers: a prior frees them (and only them)
    *_, with_prior = _fit(printer, priors=tuple(Prior(a, 215.0, 0.1) for a in ARMS))
    assert set(ARMS) <= set(with_prior.free) and not set(LEANS) & set(with_prior.free)
    # named: freed
    *_, named = _fit(printer, free=["angle_*", "radius_*", "arm_*", "endstop_*", "lean_*"], fix="auto",
                     priors=tuple(Prior(a, 215.0, 0.1) for a in ARMS))
    assert set(ARMS + LEANS) <= set(named.free)
    # which sensor holds what: heights only on the bed, lengths on the bed, lengths anywhere
    assert set(sensor_held_parameters(nominal, setup.sensor)) == set(ARMS + LEANS)
    assert set(sensor_held_parameters(nominal, setup.sensor, ["arm_*=215±0.1"])) == set(LEANS)
    from pkmcal.workflow.inputs import machine_and_setup

    pairs, printed = machine_and_setup("kossel-mini", "printed-distance-klipper")
    assert set(sensor_held_parameters(pairs, printed.sensor)) == set(LEANS)
    assert sensor_held_parameters(nominal, load_setup("laser-tracker", nominal).sensor) == ()


def test_identify_and_export_say_what_the_heights_leave_undetermined(printer):
    run = CliRunner()
    res = _invoke(run, printer, ["identify", "delta.yaml", "probe.csv", "--setup", "z-probe-klipper", "-o",
                                 "plain.yaml"])
    assert res.exit_code == 0, res.output
    line = next(ln for ln in res.output.splitlines() if ln.startswith("warning: a common scale"))
    assert "not determined by these measurements (sigma 1.5 %" in line and "--prior 'arm_*=215±0.1'" in line
    assert "this fit held arm_a, arm_b, arm_c at the machine file's values" in line
    entry, *slide = load_machine(str(printer / "plain.yaml")).metadata["calibration"]["undetermined"]
    assert entry["status"] == "not determined" and entry["held"] == list(ARMS) and not entry["placement"]
    *slide, lean = slide
    assert [(e["status"], e["placement"], e["note"], e["sigma"]) for e in slide] == [
        ("unidentifiable", True, True, None)] * 2
    assert lean["meaning"] == "the rail leans" and lean["note"] and lean["held"] == sorted(LEANS, key=LEANS_ORDER)
    assert entry["sigma"] == pytest.approx(0.0149, rel=0.02) and entry["tolerance"] == 1e-3
    for fmt, mark in (("klipper", "#"), ("marlin", ";")):
        out = _invoke(run, printer, ["export", "plain.yaml", "--format", fmt, "-o", f"plain.{fmt}"])
        assert out.exit_code == 0, out.output
        assert "pkmcal: warning: a common scale of the arm lengths and the radius: not determined" in out.output
        text = (printer / f"plain.{fmt}").read_text()
        assert text.startswith(f"{mark} pkmcal: what the calibration's measurements did not determine:")
        comments = [ln for ln in text.splitlines() if ln.startswith(mark)]
        assert "a common scale of the arm lengths" in " ".join(comments)
    # the exported Klipper sections still read as Klipper reads them (the comments are comments)
    from pkmcal.io.delta_firmware import KLIPPER_ROUNDING, read_klipper

    (printer / "back.cfg").write_text("[printer]\nkinematics: delta\n\n" + (printer / "plain.klipper").read_text())
    assert read_klipper(str(printer / "back.cfg")).arms == (215.0, 215.0, 215.0)
    # with the rods measured, nothing that shapes the print is left undetermined: only where it sits on the bed,
    # said as a note (no warning) by identify and export, and a comment in the file
    res = _invoke(run, printer, ["identify", "delta.yaml", "probe.csv", "--setup", "z-probe-klipper", "--prior",
                                 "arm_*=215±0.1", "-o", "rods.yaml"])
    assert res.exit_code == 0 and "warning: a common scale" not in res.output
    undetermined = load_machine(str(printer / "rods.yaml")).metadata["calibration"]["undetermined"]
    assert [(e["placement"], e["note"]) for e in undetermined] == [(True, True)] * 2 + [(False, True)]
    out = _invoke(run, printer, ["export", "rods.yaml", "--format", "klipper", "-o", "rods.cfg"])
    assert out.exit_code == 0 and "warning" not in out.output, out.output
    assert "pkmcal: note: where the tower set stands along x on the bed" in out.output
    comments = [ln for ln in (printer / "rods.cfg").read_text().splitlines() if ln.startswith("#")]
    assert "measure it by hand" in " ".join(comments) and "sigma unbounded" in " ".join(comments)
    # nothing on the scale; how the numbers are rounded, as every export says
    assert not any("a common scale" in ln for ln in comments) and f"# pkmcal: {KLIPPER_ROUNDING}" in comments


def test_firmware_sigmas_are_the_covariance_propagated_and_free_of_the_gauge(printer):
    """Against a Monte Carlo of the calibration's covariance through the exact rewrite (20000
    draws: the sample std is within 1/sqrt(2 N) = 0.5 % of the true one; tolerance 3 %), and
    the same under two gauges of the same fit (the slide and turn of the tower set are not
    in the firmware's numbers)."""
    priors = tuple(Prior(a, 215.0, 0.1) for a in ARMS)
    free = ["angle_*", "radius_*", "arm_*", "endstop_*"]
    _, _, _, a = _fit(printer, free=free, fix=["angle_a", "radius_a", "angle_b"], priors=priors)
    _, _, _, b = _fit(printer, free=free, fix=["angle_c", "radius_b", "radius_c"], priors=priors)
    names = list(a.mechanism.param_names)

    def cov_of(fit):
        cov = np.zeros((len(names), len(names)))
        idx = [names.index(n) for n in fit.free]
        cov[np.ix_(idx, idx)] = fit.covariance
        return cov

    sa, sb = firmware_sigmas(a.mechanism, cov_of(a)), firmware_sigmas(b.mechanism, cov_of(b))
    assert set(sa) == set(FIRMWARE_NUMBERS)
    for n in FIRMWARE_NUMBERS:
        assert sb[n] == pytest.approx(sa[n], rel=1e-3), n
    rng = np.random.default_rng(0)
    idx = [names.index(n) for n in a.free]
    draws = np.tile(a.mechanism.params, (20000, 1))
    draws[:, idx] = rng.multivariate_normal(a.mechanism.params[idx], a.covariance, size=20000)

    class P:
        def __init__(self, params):
            self.params = params

    def numbers(r):
        R, ang, E, _ = exact_rewrite(P(r))
        return np.r_[R, ang[0] - ang[2], ang[1] - ang[2], r[[names.index(x) for x in ARMS]], E]

    mc = np.std(np.array([numbers(r) for r in draws]), axis=0)
    np.testing.assert_allclose(mc, [sa[n] for n in FIRMWARE_NUMBERS], rtol=0.03)


def _identify_with_leans(run, work, output):
    """The tutorial's fit with the rail leans freed by name and the rods measured."""
    res = _invoke(run, work, ["identify", "delta.yaml", "probe.csv", "--setup", "z-probe-klipper", "--free",
                              "angle_*,radius_*,arm_*,endstop_*,lean_*", "--fix", "auto", "--prior", "arm_*=215±0.1",
                              "-o", output])
    assert res.exit_code == 0, res.output


def test_export_refuses_numbers_the_data_do_not_determine_unless_accepted(printer):
    run = CliRunner()
    _identify_with_leans(run, printer, "leans.yaml")
    out = _invoke(run, printer, ["export", "leans.yaml", "--format", "klipper", "--no-refit", "-o", "x.cfg"])
    assert out.exit_code == 2 and "the export is refused: radius_b: the measurements do not determine it" in out.output
    assert "--accept-undetermined NAME" in out.output and not (printer / "x.cfg").exists()
    accepted = ["--accept-undetermined", "radius_*", "--accept-undetermined", "angle_*", "--accept-undetermined",
                "endstop_*"]
    out = _invoke(run, printer, ["export", "leans.yaml", "--format", "klipper", "--no-refit", "-o", "x.cfg",
                                 *accepted])
    assert out.exit_code == 0, out.output
    assert "radius_b: the measurements do not determine it (sigma 0.814 mm" in (printer / "x.cfg").read_text()
    out = _invoke(run, printer, ["export", "leans.yaml", "--format", "klipper", "--accept-undetermined", "rod_a"])
    assert out.exit_code == 2 and "--accept-undetermined 'rod_a': no firmware number has this name" in out.output
    out = _invoke(run, printer, ["export", "leans.yaml", "--format", "json", "--no-refit"])
    assert out.exit_code == 2 and "--format klipper or marlin" in out.output


def test_export_refits_by_default_only_on_the_unchanged_recorded_file(printer):
    run = CliRunner()
    _identify_with_leans(run, printer, "leans2.yaml")
    out = _invoke(run, printer, ["export", "leans2.yaml", "--format", "klipper", "-o", "refit.cfg"])
    assert out.exit_code == 0 and "refitting for the firmware on the calibration's measurements probe.csv" in out.output
    # the record's file changed since identify: no refit on it, and the dropped numbers are refused
    shutil.copy(printer / "probe.csv", printer / "probe.bak")
    try:
        (printer / "probe.csv").write_text((printer / "probe.csv").read_text() + "\n")
        out = _invoke(run, printer, ["export", "leans2.yaml", "--format", "klipper", "-o", "y.cfg"])
        assert out.exit_code == 2 and "probe.csv has changed since the calibration" in out.output
        assert "the export is refused" in out.output
        (printer / "probe.csv").unlink()
        out = _invoke(run, printer, ["export", "leans2.yaml", "--format", "klipper", "-o", "y.cfg"])
        assert out.exit_code == 2 and "the calibration's measurements probe.csv are not found" in out.output
    finally:
        shutil.copy(printer / "probe.bak", printer / "probe.csv")


def test_a_refit_with_no_residual_to_spare_is_refused(printer):
    nominal, setup, meas, fit = _fit(printer)
    six = Measurements(actuators=meas.actuators[:6], readings=meas.readings[:6], commanded=meas.commanded[:6])
    with pytest.raises(PkmcalError, match="it would fit them exactly and nothing would check it"):
        firmware_refit(fit.mechanism, setup, six, priors=(),
                       free=("angle_a", "angle_b", "angle_c", "endstop_a", "endstop_b", "endstop_c"))
    with pytest.raises(PkmcalError, match="frees only the firmware's numbers"):
        firmware_refit(fit.mechanism, setup, meas, priors=(), free=("lean_radial_a",))


def test_klippers_seven_points_and_its_printed_object_take_the_default_path(printer, tmp_path):
    """Klipper's standard 7 probe points fit by default (6 free numbers, one degree of freedom
    left: the arms held), and a printed-object calibration (examples/klipper/delta-analyze.log)
    exports, with the firmware-limited refit on its pairs when asked (was refused)."""
    nominal, setup, meas, _ = _fit(printer)
    seven = Measurements(actuators=meas.actuators[:7], readings=meas.readings[:7], commanded=meas.commanded[:7])
    fit = identify(nominal, setup, seven)
    assert fit.success and fit.uncertainty.dof == 1 and len(fit.free) == 6
    run = CliRunner()
    log = str(Path(__file__).resolve().parents[2] / "examples" / "klipper" / "delta-analyze.log")
    for args in (["import", "klipper-analyze", log, "--machine", "kossel-mini", "--object-machine", "kossel-mini",
                  "-o", "pairs.csv"],
                 ["identify", "kossel-mini", "pairs.csv", "--setup", "printed-distance-klipper", "-o", "obj.yaml"],
                 ["export", "obj.yaml", "--format", "klipper", "-o", "obj.cfg"]):
        res = _invoke(run, tmp_path, args)
        assert res.exit_code == 0, (args, res.output)
    held = load_machine(str(tmp_path / "obj.yaml")).metadata["calibration"]
    assert set(ARMS) <= set(held["free"]) and not set(LEANS) & set(held["free"])
    res = _invoke(run, tmp_path, ["export", "obj.yaml", "--format", "klipper", "--calibration-measurements", "pairs.csv",
                                  "-o", "refit.cfg"])
    assert res.exit_code == 0 and "firmware-limited refit (exported)" in res.output, res.output


def test_rods_freed_from_heights_are_announced_by_identify_and_refused_by_export(printer):
    """The rods freed by name without a prior: identify warns that export will refuse them
    (their sigma 0.22 mm, over 0.1 % of the arm), and export does, until accepted by name."""
    run = CliRunner()
    res = _invoke(run, printer, ["identify", "delta.yaml", "probe.csv", "--setup", "z-probe-klipper", "--free",
                                 "angle_*,radius_*,arm_*,endstop_*", "--fix", "auto", "-o", "rods-free.yaml"])
    assert res.exit_code == 0, res.output
    warned = [ln for ln in res.output.splitlines() if "will refuse it unless accepted by name" in ln]
    assert [ln.split(":")[1].strip() for ln in warned] == list(ARMS), warned
    out = _invoke(run, printer, ["export", "rods-free.yaml", "--format", "marlin", "-o", "r.gcode"])
    assert out.exit_code == 2 and "the export is refused: arm_a: the measurements do not determine it" in out.output
    out = _invoke(run, printer, ["export", "rods-free.yaml", "--format", "marlin", "-o", "r.gcode",
                                 "--accept-undetermined", "arm_*"])
    assert out.exit_code == 0, out.output
    assert ";   arm_b: the measurements do not determine it" in (printer / "r.gcode").read_text()


def test_the_lean_advice_is_the_fits_own_sigma_and_the_block_is_seen(printer):
    """The rail leans' σ that identify's note gives (advice.plane_held_advice, from the design
    Jacobian at the nominal machine, gauge-free) against an independent one: the engine's
    covariance of a fit that frees them, gauge fixed, at its solution (the Jacobians differ
    by the fitted geometry, ~1 % of the radius, and the covariance is not rescaled by χ²:
    within 10 %). Then the advice's options in the fit's own terms: probing a gauge block
    (readings of its height at its 13 places) lowers the fitted leans' σ as the note says."""
    from pkmcal.identification.advice import BLOCK_HEIGHT, block_poses
    from pkmcal.identification.identifiability import undetermined_directions

    rods = (Prior("arm_*", 215.0, 0.1),)
    nominal, setup, meas, fit = _fit(printer, free=["angle_*", "radius_*", "arm_*", "endstop_*", "lean_*"],
                                     fix="auto", priors=rods)
    fitted = np.degrees(max(fit.std[fit.free.index(n)] for n in LEANS))
    (lean,) = [e for e in undetermined_directions(nominal, setup, meas.commanded, priors=rods)
               if e["meaning"] == "the rail leans"]
    assert lean["held"] == [] and "these measurements determine them to" in lean["text"]
    assert lean["sigma"] == pytest.approx(fitted, rel=0.1)
    # the block, measured: its 13 readings of its height added to the campaign, noise-free at the fitted machine
    poses = block_poses(nominal)
    assert np.allclose(poses[:, 2], BLOCK_HEIGHT)
    lam = fit.mechanism.ik(poses)
    both = Measurements(actuators=np.vstack([meas.actuators, lam]),
                        readings=np.vstack([meas.readings, np.full((len(poses), 1), BLOCK_HEIGHT)]),
                        commanded=np.vstack([meas.commanded, poses]))
    with_block = identify(nominal, setup, both, free=["angle_*", "radius_*", "arm_*", "endstop_*", "lean_*"],
                          fix="auto", priors=rods)
    sigma_block = np.degrees(max(with_block.std[with_block.free.index(n)] for n in LEANS))
    said = float(lean["remedy"].split("MANUAL_HEIGHT): sigma ")[1].split(" deg")[0])
    assert sigma_block < 0.5 * fitted
    assert sigma_block == pytest.approx(said, rel=0.1)
