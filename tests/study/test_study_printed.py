"""pkmcal study of a delta printer calibrated with Klipper's printed object (issue 14): a
``printed-distance`` setup's campaign is the plan's probe points as height rows and the 12
distances of Klipper's calibration object as distance rows, on the machine read as pose pairs
(``study/printed.py``), verified on single poses.

Checks: the simulated campaign is what ``pkmcal import klipper-analyze`` writes (height rows
repeat their carriage positions and read no distance, distance rows read no height, the
object's points are Klipper's, the noise-free distances the real machine's closed form); a
trial's row is what ``pkmcal identify`` and ``pkmcal verify --real`` make of the same data
through files (the default comparison, aligned, and the probe's heights, sensor); the scale is
identified with the object and not determined without, under the same gauge rule as every
setup; a process pool gives the same bytes; the fingerprint follows the object; and a
printed-distance setup on a machine that cannot print Klipper's object is refused with the
file and key."""

from __future__ import annotations


import numpy as np
import pytest
from click.testing import CliRunner
from helpers import DELTA_ERRORS_YAML, assert_user_error, trial_through_commands
from helpers import write_study as _write

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError
from pkmcal.io.klipper_analyze import object_point_pairs
from pkmcal.study import load_study, read_trials, run_study
from pkmcal.study.results import HELDOUT_COLUMNS
from pkmcal.study.trial import _measure, prepare

ERRORS = DELTA_ERRORS_YAML
#: The probe alone and the probe with the object, compared on the printed geometry.
STUDY = f"""\
name: printed
seed: 5
trials: 3
machines:
  - nominal: kossel-mini
    errors:
{ERRORS}setups:
  - {{setup: z-probe-klipper, label: probe}}
  - {{setup: printed-distance-klipper, label: object}}
plans:
  - {{algorithm: random, poses: [20]}}
methods:
  - auto
  - {{method: fk-residual, fix: ["arm_*", angle_a, radius_a, angle_b], label: rods-nominal}}
heldout: {{poses: 8, compare: aligned}}
"""
#: One printed-distance setup, the default comparison.
OBJECT = f"""\
name: object
seed: 5
trials: 2
machines:
  - nominal: kossel-mini
    errors:
{ERRORS}setups:
  - {{setup: printed-distance-klipper, label: object}}
plans:
  - {{algorithm: random, poses: [15]}}
methods: [auto]
heldout: {{poses: 8}}
"""


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    d = tmp_path_factory.mktemp("printed")
    run_study(load_study(_write(d, STUDY)), d / "r", workers=1, figures=True)
    return d


# -- the campaign ------------------------------------------------------------------------------


def test_the_campaign_is_what_the_klipper_import_writes(tmp_path):
    """Probe points as height rows (each carriage position twice, no distance), then Klipper's
    object as distance rows (no height); the noise-free distances are the real machine's
    ‖FK(IK_nominal(p_1)) − FK(IK_nominal(p_2))‖."""
    study = load_study(_write(tmp_path, OBJECT))
    ctx = prepare(study)
    campaign = ctx.campaigns[0]
    sim = _measure(ctx, campaign, 0).sim
    nominal = study.machines[0].nominal
    n = campaign.n_poses
    meas = sim.measurements
    assert len(meas) == n + 12 and list(sim.kept) == list(range(n + 12))
    q, y = meas.actuators, meas.readings
    np.testing.assert_array_equal(q[:n, :3], q[:n, 3:])
    np.testing.assert_array_equal(y[:n, 1], 0.0)
    np.testing.assert_array_equal(y[n:, 0], 0.0)
    p1, p2 = object_point_pairs()
    np.testing.assert_array_equal(meas.commanded[n:], np.c_[p1, p2])
    real = _measure(ctx, campaign, 0).real
    d = np.linalg.norm(real.fk(nominal.ik(p1)).poses - real.fk(nominal.ik(p2)).poses, axis=1)
    np.testing.assert_allclose(sim.sensor_true[n:, 1], d, rtol=1e-12)
    # the calipers' noise (0.02 mm) on the distances, the probe's on the heights
    assert 0 < np.max(np.abs(y[n:, 1] - d)) < 0.2
    np.testing.assert_array_equal(sim.actuator_true[n:], np.c_[nominal.ik(p1), nominal.ik(p2)])


def test_probe_points_on_the_bed(tmp_path):
    """``on_bed``: the plan's probe points lowered to where the probe triggers (z = 0 with the
    probe at the nozzle), every one measured on the real machine (the bed limit unchecked) and
    reading the real nozzle's height there, tenths of a mm from the endstop errors."""
    text = OBJECT.replace("label: object}", "label: object, on_bed: true}")
    study = load_study(_write(tmp_path, text))
    ctx = prepare(study)
    np.testing.assert_allclose(ctx.pools[0][:, 2], 0.0, atol=1e-9)
    campaign = ctx.campaigns[0]
    m = _measure(ctx, campaign, 0)
    n = campaign.n_poses
    assert len(m.sim.kept) == n + 12
    np.testing.assert_allclose(m.sim.measurements.commanded[:n, 2], 0.0, atol=1e-9)
    heights = m.sim.sensor_true[:n, 0]
    np.testing.assert_allclose(heights, m.sim.real_poses[:n, 2], rtol=0, atol=1e-9)
    assert 0 < np.max(np.abs(heights)) < 3.0


# -- a trial against the commands -----------------------------------------------------------------


@pytest.mark.parametrize("compare", ["auto", "sensor"])
def test_a_printed_trial_is_what_identify_and_verify_make_of_it(tmp_path, compare):
    """Trial 1 through files: `pkmcal identify` of the pair file (the machine read as pose
    pairs), then `pkmcal verify --real` on single poses: auto is the printed geometry after
    the best rigid alignment (`--compare aligned`), sensor the probe's heights (`--setup
    z-probe-klipper`, the calibration's identified probe)."""
    text = OBJECT if compare == "auto" else OBJECT.replace("heldout: {poses: 8}", "heldout: {poses: 8, compare: sensor}")
    study = load_study(_write(tmp_path, text))
    expected = "aligned" if compare == "auto" else "sensor"
    assert prepare(study).campaigns[0].compares == (expected,)
    how = ["--compare", "aligned"] if compare == "auto" else ["--setup", "z-probe-klipper"]
    row, fit, ver = trial_through_commands(tmp_path, study, 0, ["--setup", "printed-distance-klipper"], how)
    assert ver["compare"] == row["heldout_compare"] == expected
    assert fit["method"] == row["identification"] == "fk-residual"
    assert float(row["chi2"]) == pytest.approx(fit["chi2"], rel=1e-8)
    assert int(row["dof"]) == fit["dof"] and int(row["poses_measured"]) == 15 + 12
    assert int(row["heldout_used"]) == ver["after"]["poses"] == ver["before"]["poses"]
    measures = ("position", "height") if compare == "auto" else ("reading",)
    for measure in measures:
        for side, suffix in (("after", ""), ("before", "_before")):
            assert float(row[f"heldout_{measure}_rms{suffix}_mm"]) == \
                pytest.approx(ver[side][f"{measure}_rms_mm"], rel=1e-6), (measure, side)
    # the object's printed geometry lands well inside the uncalibrated one's
    if compare == "auto":
        assert float(row["heldout_position_rms_mm"]) < 0.3 * float(row["heldout_position_rms_before_mm"])


# -- what the object adds -------------------------------------------------------------------------


def test_the_scale_is_identified_with_the_object_and_not_without(both):
    """The probe alone fits fewer parameters than with the object (a sensor of heights holds
    the arms and the leans by default, the object only the leans:
    residuals.sensor_held_parameters), and
    `pkmcal identifiability`'s verdict on the delta's named direction: not determined by
    the probe alone (σ above the 0.1 % tolerance), identified with the object. Gauge and
    coverage follow the rule of every setup: the gauge parameters are fixed, not estimated,
    and only the n_free = rank estimated ones are counted."""
    cols = read_trials(both / "r" / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    probe, obj = cols["setup"] == "probe", cols["setup"] == "object"
    assert set(cols["scale_status"][probe]) == {"not determined"}
    assert set(cols["scale_status"][obj]) == {"identified"}
    assert np.all(cols["scale_sigma"][obj] < 1e-3) and np.all(cols["scale_sigma"][probe] > 1e-3)
    auto = cols["method"] == "auto"
    assert np.all(cols["rank"][auto] == cols["n_free"][auto])
    for r, n, g in zip(cols["rank"][auto], cols["n_candidates"][auto], cols["gauge"][auto]):
        assert n - r == len(g.split())
    assert max(cols["rank"][probe & auto]) < min(cols["rank"][obj & auto])
    # a method that holds the rods is asked whether the measurements would determine them
    held = cols["method"] == "rods-nominal"
    assert np.all(cols["scale_status"][probe & held] == cols["scale_status"][probe & ~held])
    assert np.all(cols["scale_status"][obj & held] == "identified")
    for name in ("coverage_fraction", "ellipsoid_within_95"):
        assert np.all((cols[name] >= 0) & (cols[name] <= 1)), name
    # what the scale is for: the printed geometry, on the same real machines
    after = cols["heldout_position_rms_mm"]
    assert np.all(after[obj & auto] < after[probe & auto]), (after[obj & auto], after[probe & auto])
    assert cols["poses_measured"][obj].tolist() == [32.0] * 6


def test_printed_rows_empty_and_summary(both):
    """Aligned: the printed geometry's position and height, no orientation, tilt or reading
    (a delta); summary.csv summarises the scale's σ, and the page names the object."""
    cols = read_trials(both / "r" / "trials.csv")
    assert set(cols["heldout_compare"]) == {"aligned"}
    for name in HELDOUT_COLUMNS:
        empty = bool(np.all(np.isnan(cols[name])))
        assert empty == any(m in name for m in ("orientation", "tilt", "reading")), name
    summary = (both / "r" / "summary.csv").read_text(encoding="utf-8")
    assert ",scale_sigma," in summary and "heldout_reading" not in summary
    page = (both / "r" / "index.html").read_text(encoding="utf-8")
    assert "Klipper&#x27;s calibration object at scale 1" in page and "scale_status" in page


def test_same_bytes_with_a_process_pool(both, tmp_path):
    pool = run_study(load_study(_write(tmp_path, STUDY)), tmp_path / "pool", workers=2, figures=False)
    assert pool.backend == "pool"
    for name in ("trials.csv", "summary.csv"):
        assert (tmp_path / "pool" / name).read_bytes() == (both / "r" / name).read_bytes(), name


def test_resume_and_the_fingerprint_follow_the_object(tmp_path):
    """--resume continues a printed study bit for bit; the object's scale and the calipers'
    noise are part of what the results depend on (the fingerprint)."""
    p = _write(tmp_path, OBJECT.replace("trials: 2", "trials: 1"))
    study = load_study(p)
    run_study(study, tmp_path / "r", workers=1, figures=False)
    run_study(study.with_trials(2), tmp_path / "r", workers=1, resume=True, figures=False)
    run_study(load_study(_write(tmp_path, OBJECT, "fresh.yaml")), tmp_path / "fresh", workers=1, figures=False)
    assert (tmp_path / "r" / "trials.csv").read_bytes() == (tmp_path / "fresh" / "trials.csv").read_bytes()
    prints = {study.fingerprint()}
    for change in ("label: object, object_scale: 0.8}", "label: object, reading_noise_scale: [1, 0.5]}",
                   "label: object, on_bed: true}"):
        prints.add(load_study(_write(tmp_path, OBJECT.replace("label: object}", change), "c.yaml")).fingerprint())
    assert len(prints) == 4
    noise = load_study(_write(tmp_path, OBJECT.replace("label: object}", "label: object, reading_noise_scale: [1, 0.5]}"),
                              "c.yaml")).setups[0].setup.noise
    np.testing.assert_array_equal(noise.reading_std, [0.005, 0.01])


# -- the study file -------------------------------------------------------------------------------

HEXAPOD = """\
name: hexapod
trials: 2
machines:
  - nominal: stewart-prototype
    errors:
      - {parameters: "*", distribution: uniform, size: 0.2}
setups:
  - {setup: printed-distance-klipper, label: object}
plans:
  - {algorithm: random, poses: [15]}
"""


@pytest.mark.parametrize("text, fragments", [
    (HEXAPOD, ("setups[0].setup", "linear delta printer", "machine 'stewart-prototype' is a 6-UPS")),
    (HEXAPOD.replace("stewart-prototype", "delta-picker").replace('"*"', '"upper_*"'),
     ("setups[0].setup", "machine 'delta-picker' is a rotary-delta")),
    (OBJECT.replace("label: object}", "label: object, object_scale: 1.6}"),
     ("setups[0].object_scale", "at scale 1.6", "outside what machine 'kossel-mini' can print", "print_radius")),
    (OBJECT.replace("printed-distance-klipper, label: object}", "z-probe-klipper, label: object, object_scale: 1}"),
     ("setups[0].object_scale", "'z-probe' sensor", "printed-distance")),
    (OBJECT.replace("label: object}", "label: object, reading_noise_scale: [1, 0.5, 2]}"),
     ("setups[0].reading_noise_scale", "3 reading noise factors for the 2 readings (probe_z, distance)")),
    (OBJECT.replace("label: object}", "label: object, object_scale: 0}"), ("setups[0].object_scale", "greater than 0")),
    (OBJECT.replace("printed-distance-klipper, label: object}", "laser-tracker, label: object, on_bed: true}"),
     ("setups[0].on_bed", "'position' sensor")),
])
def test_printed_study_file_errors(tmp_path, text, fragments):
    p = _write(tmp_path, text)
    with pytest.raises(InputFileError) as exc:
        load_study(p)
    for f in (str(p),) + fragments:
        assert f in str(exc.value), str(exc.value)
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "out")])
    assert_user_error(r, str(p), *fragments)
    assert not (tmp_path / "out").exists()


def test_too_few_probe_points_to_plan_say_why(tmp_path):
    """The probe points are planned as for the Z probe alone: a D-optimal plan needs as many
    as the probe's identifiable parameters, and says so for the printed setup."""
    p = _write(tmp_path, OBJECT.replace("{algorithm: random, poses: [15]}", "{algorithm: default, poses: [7]}"))
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "out")])
    assert_user_error(r, "plan 'default'", "setup 'object'", "planned as for its Z probe alone", "fewer than the")


def test_the_example_loads():
    from pathlib import Path

    study = load_study(Path(__file__).resolve().parents[2] / "examples" / "study-delta-printed-object.yaml")
    assert study.reads_pose_pairs
    kinds = {s.label: s.setup.sensor.kind for s in study.setups}
    assert kinds == {"probe": "z-probe", "object-0.02": "printed-distance", "object-0.01": "printed-distance"}
    np.testing.assert_array_equal(study.setups[2].setup.noise.reading_std, [0.005, 0.01])
