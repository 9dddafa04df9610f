"""The firmware-limited refit of a linear delta (issue 13, item 4): the best machine Klipper
or Marlin can hold, and what dropping the rest costs.

Checked against independent constructions, on simulated probing campaigns of a
``kossel-mini`` (the firmware lowers the nozzle down its own vertical line until the real
nozzle meets the real bed, as Klipper's PROBE does):

* a real printer the firmware can describe exactly (vertical rails, one radius): noise-free,
  the refit predicts the real printer's held-out trigger heights to round-off; with noise,
  it loses nothing against the full model beyond the chance of fitting six more numbers;
* a real printer with a leaning rail: the refit loses a measurable amount against the full
  model (beyond that chance level), and it beats dropping the lean without a refit (the
  real printer's own numbers with the lean removed);
* ``pkmcal export --measurements``: writes the refit (its Klipper config reads back to the
  refit's numbers), reports the three models on standard error and in ``--json``, and names
  its misuse.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.identification.engine import identify
from pkmcal.identification.firmware_refit import (
    FIRMWARE_FREE,
    HELD,
    dropped_machine,
    firmware_refit,
    residual_rms,
)
from pkmcal.identification.priors import Prior
from pkmcal.io.delta_firmware import firmware_subset, klipper_rounded, read_klipper
from pkmcal.io.marlin_settings import marlin_rounded
from pkmcal.io.machine_file import load_machine, machine_to_text
from pkmcal.io.measurements import Measurements
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.linear_delta import PARAM_NAMES
from pkmcal.sensors.base import NoiseModel

TRIGGER_STD = 0.005
#: The full model: every parameter but the tool offset (a Z probe's default holds the arms and
#: the leans, which heights alone do not determine; these tests fit them, with priors on the arms)
ALL = ",".join(f"{p}_*" for p in ("angle", "radius", "arm", "endstop", "lean"))


def _probe(nominal, real, sensor, xy, rng=None):
    """Carriage positions where the real probe meets the real bed while the firmware
    (``nominal``) lowers the nozzle down its vertical line (secant steps in z); with ``rng``
    the trigger scatters by TRIGGER_STD and the carriages by the setup's actuator noise."""
    target = np.zeros(len(xy)) if rng is None else rng.standard_normal(len(xy)) * TRIGGER_STD

    def height(z):
        lam = nominal.ik(np.c_[xy, z])
        return sensor.predict(real.frame(real.fk(lam).poses))[:, 0] - target, lam

    z = np.zeros(len(xy))
    for _ in range(25):
        h0, _ = height(z)
        h1, _ = height(z + 1e-3)
        z = z - h0 * 1e-3 / (h1 - h0)
    h, lam = height(z)
    assert np.max(np.abs(h)) < 1e-11
    if rng is not None:
        lam = lam + rng.standard_normal(lam.shape) * 0.0036
    return Measurements(actuators=lam, readings=np.zeros((len(xy), 1)), commanded=np.c_[xy, z])


def _disc(n, radius, rng):
    r = radius * np.sqrt(rng.uniform(size=n))
    t = rng.uniform(0, 2 * np.pi, n)
    return np.c_[r * np.cos(t), r * np.sin(t)]


def _real(nominal, rng, lean_deg=0.0):
    """The nominal printer with its Klipper numbers off by ~0.4 mm / 0.3° (one radius for all
    towers), and rail b leaning ``lean_deg`` towards the centre."""
    rho = nominal.params.copy()
    for name in ("arm_a", "arm_b", "arm_c", "endstop_a", "endstop_b", "endstop_c"):
        rho[PARAM_NAMES.index(name)] += 0.4 * rng.standard_normal()
    for name in ("angle_a", "angle_b"):
        rho[PARAM_NAMES.index(name)] += np.deg2rad(0.3) * rng.standard_normal()
    for t in "abc":
        rho[PARAM_NAMES.index(f"radius_{t}")] -= 0.5
    rho[PARAM_NAMES.index("lean_radial_b")] = np.deg2rad(lean_deg)
    return nominal.with_params(rho, name="real")


def _arm_priors(real, rng):
    """The rods measured to ±0.1 mm (the tutorial's --prior 'arm_*=215±0.1')."""
    return tuple(Prior(f"arm_{t}", float(real.params[PARAM_NAMES.index(f"arm_{t}")] + 0.1 * rng.standard_normal()),
                       0.1) for t in "abc")


def _noise_free(setup):
    return dataclasses.replace(setup, noise=NoiseModel(reading_std=np.zeros(1), actuator_std=np.array(0.0)))


def _campaign(seed, lean_deg, noisy=True, n=60, n_held=40):
    nominal = load_machine("kossel-mini")
    setup = load_setup("z-probe-klipper", nominal)
    rng = np.random.default_rng(seed)
    real = _real(nominal, rng, lean_deg)
    meas = _probe(nominal, real, setup.sensor, _disc(n, 80, rng), rng if noisy else None)
    held = _probe(nominal, real, setup.sensor, _disc(n_held, 85, rng), rng if noisy else None)
    return nominal, setup, real, meas, held, _arm_priors(real, rng)


def _chance_limit(full, n_poses, n_more):
    """Largest rms² gain (refit over full) that fitting ``n_more`` more numbers gives by
    chance: Δχ² of n_more dof, mean n_more, here bounded at its mean + 5 std, in the units of
    the full fit's per-pose noise variance (rms² · N/(N − p), p = 15 free parameters)."""
    sigma2 = full ** 2 * n_poses / (n_poses - 15)
    return sigma2 * (n_more + 5 * np.sqrt(2 * n_more)) / n_poses


def test_noise_free_refit_of_a_firmware_representable_printer_predicts_it_exactly():
    nominal, setup, _, meas, held, _ = _campaign(11, 0.0, noisy=False)
    clean = _noise_free(setup)
    # the full model, fitted on weighted rows with a noise-free setup's weights undefined: use
    # the noisy setup's weights (the data are exact either way)
    full = identify(nominal, setup, meas, free=ALL.split(","), fix="auto", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    assert full.success and full.rms_residual < 1e-8
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=(), free=FIRMWARE_FREE)
    assert ref.refit.fit_rms["mm"] < 1e-8 and ref.refit.heldout_rms["mm"] < 1e-8
    # independently of the fit: the real printer's held-out triggers read 0 on the refit
    cal = ref.machine
    y = clean.sensor.predict(cal.frame(cal.fk(held.actuators).poses))
    np.testing.assert_allclose(y, 0.0, rtol=0, atol=1e-8)
    # the refit is a firmware machine: vertical rails, one radius, no tool offset
    _, left = firmware_subset(cal)
    assert left == []
    assert all(cal.params[PARAM_NAMES.index(n)] == 0.0 for n in HELD)


def test_a_printer_without_leans_loses_nothing_to_the_firmware():
    nominal, setup, _, meas, held, priors = _campaign(3, 0.0)
    full = identify(nominal, setup, meas, priors=priors)
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=priors)
    f, r = ref.full.fit_rms["mm"], ref.refit.fit_rms["mm"]
    assert f == pytest.approx(full.rms_residual, rel=1e-9)     # the score is the fit's own residual
    assert f <= r <= np.sqrt(f ** 2 + _chance_limit(f, 60, 6))
    # held out: within the noise of each other (the full model's six extra numbers fit noise)
    hf, hr = ref.full.heldout_rms["mm"], ref.refit.heldout_rms["mm"]
    assert abs(hr - hf) < 0.25 * hf and hr < 2.5 * TRIGGER_STD


def test_the_firmwares_resolution_changes_the_held_out_figure_far_below_the_noise():
    """The numbers as Klipper (6 decimals) and Marlin (32-bit floats) hold them, scored on the
    held-out probe heights as the refit is: the held-out rms moves by less than a hundredth of
    the probe's noise (measured on the delta tutorial: 1.3e-7 mm for Klipper, 2.5e-6 mm for
    Marlin, against a held-out rms of 8.7e-3 mm)."""
    nominal, setup, _, meas, held, priors = _campaign(3, 0.0)
    full = identify(nominal, setup, meas, priors=priors)
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=priors)
    m = ref.machine
    fw, left = firmware_subset(m)
    assert left == [] and fw.origin == (0.0, 0.0)        # one radius, no tool offset: the numbers are the params
    fitted = dataclasses.replace(setup, sensor=ref.refit.sensor)

    def machine_of(f):
        rho = m.params.copy()
        for i, t in enumerate("abc"):
            for name, v in (("angle", np.deg2rad(f.angles_deg[i])), ("radius", f.radius), ("arm", f.arms[i]),
                            ("endstop", f.endstops[i])):
                rho[PARAM_NAMES.index(f"{name}_{t}")] = v
        return m.with_params(rho)

    exact, _ = residual_rms(machine_of(fw), fitted, held, ref.method)
    assert exact["mm"] == pytest.approx(ref.refit.heldout_rms["mm"], rel=1e-9)   # the params are the numbers
    for rounded in (klipper_rounded(fw), marlin_rounded(fw)):
        assert rounded != fw
        got, _ = residual_rms(machine_of(rounded), fitted, held, ref.method)
        assert abs(got["mm"] - exact["mm"]) < 0.01 * TRIGGER_STD


def test_unequal_radii_on_vertical_rails_cost_nothing_without_a_refit():
    """A calibration with the rails held vertical (its gauge puts the sideways slide into
    unequal radii): the firmware's numbers are its exact rewrite (io/delta_firmware.py), so
    they score as the full model on the probe heights, fitted and held out, and the refit
    cannot do better."""
    nominal, setup, _, meas, held, priors = _campaign(3, 0.0)
    free = [f"{p}_{t}" for p in ("angle", "radius", "arm", "endstop") for t in "abc"]
    full = identify(nominal, setup, meas, free=free, fix="auto", priors=priors)
    radii = full.mechanism.params[[PARAM_NAMES.index(f"radius_{t}") for t in "abc"]]
    assert np.ptp(radii) > 0.1                          # unequal: the mean would have cost
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=priors)
    assert ref.dropped.fit_rms["mm"] == pytest.approx(ref.full.fit_rms["mm"], rel=1e-9)
    assert ref.dropped.heldout_rms["mm"] == pytest.approx(ref.full.heldout_rms["mm"], rel=1e-9)
    assert ref.refit.fit_rms["mm"] >= ref.full.fit_rms["mm"] * (1 - 1e-6)


def test_a_leaning_rail_costs_a_measurable_amount_and_the_refit_beats_dropping_it():
    nominal, setup, real, meas, held, priors = _campaign(5, 0.5)
    full = identify(nominal, setup, meas, free=ALL.split(","), fix="auto", priors=priors)
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=priors)
    f, r = ref.full.fit_rms["mm"], ref.refit.fit_rms["mm"]
    assert r ** 2 - f ** 2 > _chance_limit(f, 60, 6)      # beyond what six numbers gain by chance
    assert ref.refit.heldout_rms["mm"] > 1.2 * ref.full.heldout_rms["mm"]
    # dropping the lean from the real printer itself (its true numbers, no refit) is worse
    no_lean = real.with_params(np.where(np.isin(PARAM_NAMES, HELD), 0.0, real.params))
    (naive, _), (naive_held, _) = residual_rms(no_lean, setup, meas, "fk-residual"), \
        residual_rms(no_lean, setup, held, "fk-residual")
    assert ref.refit.fit_rms["mm"] < 0.5 * naive["mm"]
    assert ref.refit.heldout_rms["mm"] < 0.5 * naive_held["mm"]
    # and so is writing the calibrated machine's firmware numbers without a refit
    assert ref.dropped.heldout_rms["mm"] > 2 * ref.refit.heldout_rms["mm"]
    assert ref.dropped.machine == dropped_machine(full.mechanism)


def _files(tmp_path, seed=5, lean_deg=0.3):
    nominal, _, _, meas, held, priors = _campaign(seed, lean_deg, n=40, n_held=20)
    for name, m in (("meas.csv", meas), ("held.csv", held)):
        rows = np.c_[m.actuators, m.readings, m.commanded]
        (tmp_path / name).write_text("lambda1,lambda2,lambda3,probe_z,cmd_x,cmd_y,cmd_z\n"
                                     + "\n".join(",".join(repr(float(v)) for v in row) for row in rows) + "\n")
    (tmp_path / "nominal.yaml").write_text(machine_to_text(nominal))
    return priors


def test_export_with_measurements_writes_the_refit_and_reports_the_cost(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    priors = _files(tmp_path)
    runner = CliRunner()
    args = ["identify", "nominal.yaml", "meas.csv", "--setup", "z-probe-klipper", "--free", ALL, "--fix", "auto",
            "-o", "cal.yaml"]
    for p in priors:
        args += ["--prior", f"{p.pattern}={p.mean!r}±{p.std!r}"]
    assert runner.invoke(cli, args).exit_code == 0
    # without --measurements: the refit on the measurements the calibration record names
    default = runner.invoke(cli, ["export", "cal.yaml", "--format", "klipper", "-o", "default.cfg"])
    assert default.exit_code == 0, default.output
    assert "refitting for the firmware on the calibration's measurements meas.csv" in default.output
    # the calibrated numbers without the refit: the leans traded with the radii, endstops and
    # angles leave those with sigmas far beyond tolerance: refused unless accepted by name
    plain = runner.invoke(cli, ["export", "cal.yaml", "--format", "klipper", "--no-refit", "-o", "plain.cfg"])
    assert plain.exit_code == 2 and "the export is refused" in plain.output and "radius_b" in plain.output
    assert not (tmp_path / "plain.cfg").exists()
    plain = runner.invoke(cli, ["export", "cal.yaml", "--format", "klipper", "--no-refit", "-o", "plain.cfg",
                                "--accept-undetermined", "radius_*", "--accept-undetermined", "angle_*",
                                "--accept-undetermined", "endstop_*"])
    assert plain.exit_code == 0 and "--calibration-measurements MEAS.csv --setup SETUP" in plain.output, plain.output
    assert "exported as accepted with --accept-undetermined" in plain.output
    assert "# pkmcal:" in (tmp_path / "plain.cfg").read_text()
    res = runner.invoke(cli, ["export", "cal.yaml", "--format", "klipper", "--calibration-measurements", "meas.csv",
                              "--held-out", "held.csv", "-o", "refit.cfg"])   # setup from the calibration record
    assert res.exit_code == 0, res.output
    assert "firmware-limited refit (fk-residual" in res.output and "priors from the calibration: arm_a=" in res.output
    assert "exported settings are the firmware-limited refit" in res.output
    # the written config is the refit, computed independently through the Python API
    cal = load_machine("cal.yaml")
    setup = load_setup("z-probe-klipper", cal)
    from pkmcal.io.measurements import load_measurements

    ref = firmware_refit(cal, setup, load_measurements("meas.csv", cal, setup),
                         load_measurements("held.csv", cal, setup))
    # the export is the sections SAVE_CONFIG writes: under a printer.cfg's [printer] kinematics
    (tmp_path / "printer.cfg").write_text("[printer]\nkinematics: delta\n\n" + (tmp_path / "refit.cfg").read_text())
    back = read_klipper("printer.cfg")
    fw = klipper_rounded(firmware_subset(ref.machine)[0])      # as Klipper's SAVE_CONFIG writes them: 6 decimals
    assert (back.radius, back.angles_deg, back.arms, back.endstops) == (fw.radius, fw.angles_deg, fw.arms,
                                                                         fw.endstops)
    assert (tmp_path / "refit.cfg").read_text() != (tmp_path / "plain.cfg").read_text()
    assert (tmp_path / "refit.cfg").read_text() == (tmp_path / "default.cfg").read_text()
    line = next(ln for ln in res.output.splitlines() if "firmware-limited refit (exported)" in ln)
    assert f"{ref.refit.heldout_rms['mm']:.4g} mm" in line
    js = runner.invoke(cli, ["export", "cal.yaml", "--format", "marlin", "--calibration-measurements", "meas.csv", "--setup",
                             "z-probe-klipper", "--held-out", "held.csv", "--json", "-o", "m.gcode"])
    assert js.exit_code == 0, js.output
    d = json.loads(js.stdout)
    models = {m["model"]: m for m in d["firmware_refit"]["models"]}
    assert set(models) == {"full model (every parameter)", "firmware numbers, not refitted",
                           "firmware-limited refit (exported)"}
    assert models["firmware-limited refit (exported)"]["heldout_rms"]["mm"] == pytest.approx(
        ref.refit.heldout_rms["mm"], rel=1e-6)
    assert d["format"] == "marlin" and d["output"] == "m.gcode"


@pytest.mark.parametrize("args, fragment", [
    (["--held-out", "held.csv"], "give --calibration-measurements"),
    (["--calibration-measurements", "meas.csv", "--json"], "-o FILE"),
    (["--calibration-measurements", "meas.csv"], "no calibration record naming its setup"),
])
def test_export_refit_misuse_is_named(tmp_path, monkeypatch, args, fragment):
    monkeypatch.chdir(tmp_path)
    _files(tmp_path)
    res = CliRunner().invoke(cli, ["export", "nominal.yaml", "--format", "klipper", *args])
    assert res.exit_code == 2 and fragment in res.output, res.output


def test_export_refit_needs_a_firmware_format_and_a_linear_delta(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _files(tmp_path)
    runner = CliRunner()
    res = runner.invoke(cli, ["export", "nominal.yaml", "--format", "json", "--calibration-measurements", "meas.csv"])
    assert res.exit_code == 2 and "--format klipper or marlin" in res.output
    res = runner.invoke(cli, ["export", "stewart-prototype", "--format", "klipper", "--calibration-measurements", "meas.csv",
                              "--setup", "z-probe-klipper"])
    assert res.exit_code == 2 and "linear delta" in res.output


def test_a_setup_that_frees_the_bed_tilt_has_it_fitted_for_every_model(tmp_path):
    """The sensor parameters a setup frees (here the bed tilt) are fitted for each model on
    the fit measurements: the full model's score is then its own fit's residual, and the
    refit's bed tilt is the real one within the fit's σ."""
    from pkmcal.sensors.z_probe import ZProbeSensor

    path = tmp_path / "tilted.yaml"
    path.write_text("sensor: z-probe\nfree: [bed.a, bed.b]\nnoise: {reading: 0.005, actuator: 0.0036}\n")
    nominal = load_machine("kossel-mini")
    setup = load_setup(str(path), nominal)
    rng = np.random.default_rng(8)
    real = _real(nominal, rng)
    real_bed = ZProbeSensor(probe_offset=[0.0, 0.0, 0.0], bed=[0.0, np.deg2rad(0.08), np.deg2rad(-0.05)])
    meas = _probe(nominal, real, real_bed, _disc(60, 80, rng), rng)
    held = _probe(nominal, real, real_bed, _disc(30, 85, rng), rng)
    priors = _arm_priors(real, rng)
    full = identify(nominal, setup, meas, priors=priors)
    assert {"bed.a", "bed.b"} <= set(full.free)
    ref = firmware_refit(full.mechanism, setup, meas, held, priors=priors)
    assert ref.full.fit_rms["mm"] == pytest.approx(full.rms_residual, rel=1e-6)
    assert {"bed.a", "bed.b"} <= set(ref.free)
    k = [list(setup.sensor.param_names).index(n) for n in ("bed.a", "bed.b")]
    sd = full.std[[full.free.index(n) for n in ("bed.a", "bed.b")]]
    assert np.all(np.abs(ref.refit.sensor.params[k] - real_bed.params[k]) < 4 * sd)
    # the full model judged with the setup's level bed instead would be far worse
    level, _ = residual_rms(full.mechanism, setup, meas, "fk-residual")
    assert level["mm"] > 3 * ref.full.fit_rms["mm"]
    assert ref.refit.heldout_rms["mm"] < 2.5 * TRIGGER_STD
