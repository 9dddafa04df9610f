"""pkmcal study on every built-in machine kind: a linear delta (pose x, y, z: no orientation),
paper 3's redundantly actuated planar machines (they settle at static equilibrium and are
verified on their tool point, as ``pkmcal verify --real`` does), 6-PUS and 6-RSS hexapods, a
rotary delta, and several kinds in one study. The checks are physical: calibration with a precise sensor brings the
held-out errors well below the nominal model's, a Z probe calibrates the heights it sees, a
measure the machine does not have stays empty and is not summarised, a planar trial is what
``pkmcal identify`` and ``pkmcal verify`` make of the same data, and a process pool gives the
same bytes as one process."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import DELTA_ERRORS_YAML, assert_user_error, trial_through_commands
from helpers import write_study as _write

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError
from pkmcal.study import load_study, read_trials, run_study
from pkmcal.study.results import HELDOUT_COLUMNS
from pkmcal.study.trial import prepare

DELTA_ERRORS = DELTA_ERRORS_YAML
# A laser tracker whose target offset is known (fixed), that method only on the tracker,
# the Z probe with every parameter free; the held-out errors are what each instrument reads
# (compare: sensor, the default for instruments that do not read the full pose).
DELTA = f"""\
name: delta
seed: 5
trials: 3
machines:
  - nominal: kossel-mini
    errors:
{DELTA_ERRORS}setups:
  - {{setup: laser-tracker, label: tracker}}
  - {{setup: z-probe-klipper, label: probe}}
plans:
  - {{algorithm: random, poses: [20, 30]}}
methods:
  - {{method: auto, fix: ["target.*"], label: target-known, setups: [tracker]}}
  - {{method: auto, label: all-free, setups: [probe]}}
heldout: {{poses: 8}}
"""
PLANAR = """\
name: planar
seed: 2
trials: 3
machines:
  - nominal: planar-3dof-4act
    errors:
      - {parameters: "[Lyr]*", distribution: uniform, size: 0.5}
      - {parameters: "dq*", distribution: uniform, size: 0.5}
      - {parameters: "alpha*", distribution: uniform, size: 0.1}
  - nominal: planar-2dof-3act
    errors:
      - {parameters: "[lBD]*", distribution: uniform, size: 0.5}
      - {parameters: "dq*", distribution: uniform, size: 0.1}
setups:
  - {setup: planar-tracker, label: tracker}
plans:
  - {algorithm: random, poses: [15]}
methods: [auto]
heldout: {poses: 8}
"""
HEXASLIDE = """\
name: hexaslide
seed: 2
trials: 3
machines:
  - nominal: hexaslide
    errors:
      - {parameters: "[ra]?.?", distribution: uniform, size: 0.2}
      - {parameters: "leg_*", distribution: uniform, size: 0.2}
      - {parameters: "offset_*", distribution: uniform, size: 0.2}
setups:
  - {setup: full-pose-paper1, label: full-pose}
plans:
  - {algorithm: random, poses: [30]}
methods: [auto]
heldout: {poses: 8}
"""
# Rotary actuators (6-RSS servos, a rotary delta's motors): the built-in setups' actuator
# noise is in the actuator's unit, rad for a motor (0.005 rad = 0.29 deg, meant for a
# hexapod's legs in mm), scaled here to 5e-5 rad (0.003 deg, a fine encoder).
ROTARY = """\
name: rotary
seed: 4
trials: 3
machines:
  - nominal: servo-stewart
    errors:
      - {parameters: "[sa]?.?", distribution: uniform, size: 0.2}
      - {parameters: "crank_*", distribution: uniform, size: 0.2}
      - {parameters: "rod_*", distribution: uniform, size: 0.2}
      - {parameters: "zero_*", distribution: uniform, size: 0.1}
    setups: [full-pose]
  - nominal: delta-picker
    errors:
      - {parameters: "upper_*", distribution: uniform, size: 0.2}
      - {parameters: "forearm_*", distribution: uniform, size: 0.2}
      - {parameters: "zero_*", distribution: uniform, size: 0.1}
    setups: [tracker]
setups:
  - {setup: full-pose-paper1, label: full-pose, actuator_noise_scale: 0.01}
  - {setup: laser-tracker, label: tracker, actuator_noise_scale: 0.01}
plans:
  - {algorithm: random, poses: [30]}
methods:
  - {method: auto, machines: [servo-stewart]}
  - {method: auto, fix: ["target.*"], label: target-known, machines: [delta-picker]}
heldout: {poses: 8}
"""
MIXED = f"""\
name: mixed
seed: 7
trials: 4
machines:
  - nominal: stewart-prototype
    errors:
      - {{parameters: "*", distribution: uniform, size: 0.2}}
    ignore_limits: [leg_collision]
    setups: [full-pose]
  - nominal: kossel-mini
    errors:
{DELTA_ERRORS}    setups: [probe]
  - nominal: planar-3dof-4act
    errors:
      - {{parameters: "[Lyr]*", distribution: uniform, size: 0.5}}
    setups: [planar]
setups:
  - {{setup: full-pose-paper1, label: full-pose}}
  - {{setup: z-probe-klipper, label: probe}}
  - {{setup: planar-tracker, label: planar}}
plans:
  - {{algorithm: random, poses: [30]}}
methods: [auto]
heldout: {{poses: 6}}
"""


def _run(tmp_path_factory, text, figures=False, workers=1):
    d = tmp_path_factory.mktemp("study")
    run = run_study(load_study(_write(d, text)), d / "r", workers=workers, figures=figures)
    return run, d / "r"


def _summary(out) -> list[dict]:
    with open(out / "summary.csv", encoding="utf-8", newline="") as fh:
        return list(csv.DictReader(fh))


def _empty(cols, name) -> bool:
    return bool(np.all(np.isnan(cols[name])))


def _coverage_in_unit_interval(cols) -> None:
    for name in ("coverage_fraction", "all_within_95", "ellipsoid_within_95"):
        v = cols[name][np.isfinite(cols[name])]
        assert v.size and np.all((v >= 0.0) & (v <= 1.0)), name


@pytest.fixture(scope="module")
def delta(tmp_path_factory):
    return _run(tmp_path_factory, DELTA, figures=True)


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    return _run(tmp_path_factory, MIXED)


# -- a delta ------------------------------------------------------------------------------------


def test_delta_calibrated_by_a_tracker_lands_closer(delta):
    run, out = delta
    cols = read_trials(out / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    # each method on its own setup: configurations numbered over the pairs that exist
    assert list(cols["config"]) == [0] * 3 + [1] * 3 + [2] * 3 + [3] * 3
    assert [(s, m) for s, m in zip(cols["setup"][::3], cols["method"][::3])] == \
        [("tracker", "target-known")] * 2 + [("probe", "all-free")] * 2
    assert json.loads((out / "run.json").read_text())["configurations"] == 4
    # neither instrument reads the full pose: the held-out errors are what it reads
    assert set(cols["heldout_compare"]) == {"sensor"}
    tracker = cols["setup"] == "tracker"
    # tracker noise 0.01 mm on 20-30 poses against build errors of tenths of a mm: the
    # calibrated model brings the target several times closer than the nominal one
    after, before = cols["heldout_position_rms_mm"][tracker], cols["heldout_position_rms_before_mm"][tracker]
    assert np.all(before > 0.1) and np.all(after < 0.2 * before), (after, before)
    # the probe's readings are bed heights (0.005 mm noise): after calibration they fall
    after, before = cols["heldout_reading_rms_mm"][~tracker], cols["heldout_reading_rms_before_mm"][~tracker]
    assert np.all(after < 0.2 * before), (after, before)
    _coverage_in_unit_interval(cols)


def test_delta_cells_are_what_each_instrument_reads(delta):
    """A tracker reads a position, a Z probe only its readings: every other held-out cell is
    empty, and summary.csv has no row for it (no mean of an empty set)."""
    run, out = delta
    cols = read_trials(out / "trials.csv")
    tracker = cols["setup"] == "tracker"
    for name in HELDOUT_COLUMNS:
        sub = {k: v[tracker] for k, v in cols.items()}
        assert _empty(sub, name) == ("position" not in name), name
        sub = {k: v[~tracker] for k, v in cols.items()}
        assert _empty(sub, name) == ("reading" not in name), name
    by_config: dict[int, set] = {}
    for r in _summary(out):
        assert r["heldout_compare"] == "sensor"
        by_config.setdefault(int(r["config"]), set()).add(r["metric"])
    for config, metrics in by_config.items():
        held = {m for m in metrics if m.startswith("heldout_")}
        kind = "position" if config < 2 else "reading"
        assert held and all(kind in m for m in held), (config, held)
    # the summary's means are the trial table's
    for r in _summary(out):
        if r["metric"] == "heldout_position_rms_mm":
            v = cols["heldout_position_rms_mm"][cols["config"] == int(r["config"])]
            assert float(r["mean"]) == pytest.approx(v.mean(), rel=1e-12) and int(r["n"]) == v.size


def test_delta_page_and_figures(delta):
    run, out = delta
    page = (out / "index.html").read_text(encoding="utf-8")
    assert "nan" not in page.lower().replace("nano", "")
    assert "<svg" in page and "rms reading error" in page      # the probe's lines: its readings
    assert "held-out errors compare" in page
    for name in ("error-vs-poses", "distributions", "coverage"):
        assert (out / "figures" / f"{name}.svg").stat().st_size > 0


@pytest.mark.parametrize("compare", ["auto", "aligned"])
def test_delta_trial_is_what_identify_and_verify_make_of_it(tmp_path, compare):
    """Trial 1 of the tracker configuration, fitted and verified by the commands through
    files: the row's held-out errors are `pkmcal verify --real`'s (auto, with `--setup`:
    sensor, what the tracker reads; aligned: the platform frames after the best rigid
    alignment). With sensor, the study's "before" is the nominal machine with the setup's
    tracker as given, while `verify` registers the tracker to the nominal machine first (a
    smaller "before"), so only "after" is compared there."""
    text = DELTA if compare == "auto" else DELTA.replace("heldout: {poses: 8}", "heldout: {poses: 8, compare: aligned}")
    study = load_study(_write(tmp_path, text))
    expected = "sensor" if compare == "auto" else "aligned"
    assert prepare(study).campaigns[0].compares == (expected,)
    how = ["--setup", "laser-tracker"] if compare == "auto" else ["--compare", "aligned"]
    row, fit, ver = trial_through_commands(tmp_path, study, 0, ["--setup", "laser-tracker", "--fix", "target.*"], how)
    assert ver["compare"] == row["heldout_compare"] == expected
    assert float(row["chi2"]) == pytest.approx(fit["chi2"], rel=1e-8)
    assert int(row["heldout_used"]) == ver["after"]["poses"]
    sides = ("after",) if compare == "auto" else ("after", "before")
    for side in sides:
        suffix = "" if side == "after" else "_before"
        assert float(row[f"heldout_position_rms{suffix}_mm"]) == pytest.approx(ver[side]["position_rms_mm"], rel=1e-6)
    if compare == "aligned":
        assert float(row["heldout_height_rms_mm"]) == pytest.approx(ver["after"]["height_rms_mm"], rel=1e-6)
        assert float(row["heldout_position_rms_mm"]) < 0.2 * float(row["heldout_position_rms_before_mm"])


def test_poses_as_commanded_on_request(tmp_path_factory):
    """``compare: commanded`` keeps the platform poses as commanded, the papers' figures: a
    delta has its position and height errors there, no orientation or tilt, no readings."""
    run, out = _run(tmp_path_factory, DELTA.replace("heldout: {poses: 8}", "heldout: {poses: 8, compare: commanded}"))
    cols = read_trials(out / "trials.csv")
    assert set(cols["heldout_compare"]) == {"commanded"}
    for name in HELDOUT_COLUMNS:
        assert _empty(cols, name) == any(m in name for m in ("orientation", "tilt", "reading")), name
    tracker = cols["setup"] == "tracker"
    assert np.all(cols["heldout_height_rms_mm"][tracker] < cols["heldout_height_rms_before_mm"][tracker])


def test_a_z_probe_calibrates_the_heights_it_sees(mixed):
    run, out = mixed
    cols = read_trials(out / "trials.csv")
    probe = cols["setup"] == "probe"
    assert probe.sum() == 4 and np.all(cols["failed"][probe] == 0), cols["message"][probe]
    assert np.all(cols["identification"][probe] == "fk-residual")
    # the probe reads heights (0.005 mm) of a flat bed: what it reads falls to the noise
    # level; the in-plane scale it barely sees (docs/tutorial-delta-printer.md) is no reading
    assert np.all(cols["heldout_compare"][probe] == "sensor")
    assert np.all(cols["heldout_reading_rms_mm"][probe] < 0.1 * cols["heldout_reading_rms_before_mm"][probe])
    # the full-pose hexapod of the same study: poses as commanded; the planar machine: its tool
    assert set(cols["heldout_compare"][cols["setup"] == "full-pose"]) == {"commanded"}
    assert set(cols["heldout_compare"][cols["setup"] == "planar"]) == {"tool"}


# -- planar machines at equilibrium --------------------------------------------------------------


@pytest.fixture(scope="module")
def planar(tmp_path_factory):
    d = tmp_path_factory.mktemp("planar")
    study = load_study(_write(d, PLANAR))
    run_study(study, d / "r", workers=1, figures=False)
    return study, d


def test_planar_tool_errors_fall_and_keep_their_columns(planar):
    study, d = planar
    cols = read_trials(d / "r" / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    assert set(cols["identification"]) == {"projection"}
    after, before = cols["heldout_position_rms_mm"], cols["heldout_position_rms_before_mm"]
    assert np.all(after < 0.2 * before), (after, before)
    three = cols["machine"] == "planar-3dof-4act"
    assert np.all(np.isfinite(cols["heldout_orientation_rms_deg"][three]))          # the plate angle
    assert np.all(cols["heldout_orientation_rms_deg"][three] < cols["heldout_orientation_rms_before_deg"][three])
    assert _empty({k: v[~three] for k, v in cols.items() if k.startswith("heldout")}, "heldout_orientation_rms_deg")
    for name in ("heldout_tilt_rms_deg", "heldout_height_rms_mm", "heldout_height_rms_before_mm"):
        assert _empty(cols, name)
    _coverage_in_unit_interval(cols)


def test_planar_trial_is_what_identify_and_verify_make_of_it(planar, tmp_path):
    """Trial 1 of planar-3dof-4act: the study's simulated campaign, fitted and verified by the
    commands (through files, so to the files' round trip) gives the trial's row."""
    study, _ = planar
    row, fit, ver = trial_through_commands(tmp_path, study, 0, ["--setup", "planar-tracker"], ["--setup", "planar-tracker"])
    assert fit["method"] == row["identification"] == "projection"
    assert float(row["chi2"]) == pytest.approx(fit["chi2"], rel=1e-8)
    assert int(row["heldout_used"]) == ver["after"]["poses"] == ver["before"]["poses"]
    for col, side, key in (("heldout_position_rms_mm", "after", "tool_rms_mm"),
                           ("heldout_position_max_mm", "after", "tool_max_mm"),
                           ("heldout_position_rms_before_mm", "before", "tool_rms_mm"),
                           ("heldout_orientation_rms_deg", "after", "angle_rms_deg"),
                           ("heldout_orientation_rms_before_deg", "before", "angle_rms_deg")):
        assert float(row[col]) == pytest.approx(ver[side][key], rel=1e-6), col


# -- a 6-PUS hexapod ----------------------------------------------------------------------------


def test_hexaslide_calibrated_by_full_pose(tmp_path_factory):
    run, out = _run(tmp_path_factory, HEXASLIDE)
    cols = read_trials(out / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    assert np.all(cols["identification"] == "ik-residual")
    for measure, unit in (("position", "mm"), ("orientation", "deg"), ("tilt", "deg")):
        after, before = cols[f"heldout_{measure}_rms_{unit}"], cols[f"heldout_{measure}_rms_before_{unit}"]
        assert np.all(np.isfinite(after)) and np.all(after < 0.5 * before), measure
    _coverage_in_unit_interval(cols)


def test_rotary_actuators_calibrated_with_fine_encoders(tmp_path_factory):
    run, out = _run(tmp_path_factory, ROTARY)
    cols = read_trials(out / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    assert list(zip(cols["machine"][::3], cols["method"][::3])) == [("servo-stewart", "auto"),
                                                                    ("delta-picker", "target-known")]
    after, before = cols["heldout_position_rms_mm"], cols["heldout_position_rms_before_mm"]
    assert np.all(after < 0.2 * before), (after, before)
    rss = cols["machine"] == "servo-stewart"
    assert np.all(cols["heldout_orientation_rms_deg"][rss] < 0.5 * cols["heldout_orientation_rms_before_deg"][rss])
    assert np.all(np.isnan(cols["heldout_orientation_rms_deg"][~rss]))
    _coverage_in_unit_interval(cols)


# -- several kinds in one study ------------------------------------------------------------------


def test_mixed_study_configurations_and_columns(mixed):
    run, out = mixed
    cols = read_trials(out / "trials.csv")
    pairs = sorted({(m, s) for m, s in zip(cols["machine"], cols["setup"])})
    assert pairs == [("kossel-mini", "probe"), ("planar-3dof-4act", "planar"), ("stewart-prototype", "full-pose")]
    assert list(cols["config"]) == [0] * 4 + [1] * 4 + [2] * 4
    assert np.all(cols["failed"] == 0), cols["message"]
    hexapod, delta = cols["machine"] == "stewart-prototype", cols["machine"] == "kossel-mini"
    assert np.all(np.isfinite(cols["heldout_orientation_rms_deg"][hexapod]))
    assert np.all(np.isfinite(cols["heldout_tilt_rms_deg"][hexapod]))
    assert np.all(np.isnan(cols["heldout_orientation_rms_deg"][delta]))
    assert np.all(np.isnan(cols["heldout_orientation_max_deg"][delta]))
    assert np.all(cols["heldout_position_rms_mm"][hexapod] < cols["heldout_position_rms_before_mm"][hexapod])
    _coverage_in_unit_interval(cols)
    by_config = {}
    for r in _summary(out):
        by_config.setdefault(int(r["config"]), set()).add(r["metric"])
    assert "heldout_orientation_rms_deg" in by_config[0 if cols["machine"][0] == "stewart-prototype" else 2]
    assert "heldout_orientation_rms_deg" not in by_config[int(cols["config"][delta][0])]


def test_same_bytes_with_a_process_pool(mixed, tmp_path):
    run, out = mixed
    study = load_study(_write(tmp_path, MIXED))
    pool = run_study(study, tmp_path / "pool", workers=2, figures=False)
    assert pool.backend == "pool"
    for name in ("trials.csv", "summary.csv"):
        assert (tmp_path / "pool" / name).read_bytes() == (out / name).read_bytes(), name


# -- the study file ------------------------------------------------------------------------------


@pytest.mark.parametrize("change, fragments", [
    # one group over a delta's mm and degree parameters: named, with their units
    ((DELTA_ERRORS, '      - {parameters: "*", distribution: uniform, size: 0.3}\n'),
     ("machines[0].errors[0].parameters", "mixes length and angle parameters of 'kossel-mini'", "radius_a",
      "(mm)", "angle_a", "(deg)", "separate groups")),
    ((DELTA_ERRORS, '      - {parameters: "b*", distribution: uniform, size: 0.3}\n'),
     ("matches no parameter of 'kossel-mini'", "endstop_c", "lean_radial_a", "(deg)")),
    (("setup: laser-tracker", "setup: planar-tracker"), ("setups[0].setup", "cannot measure machine 'kossel-mini'")),
    (("heldout: {poses: 8}", "heldout: {poses: 8, compare: as-commanded}"), ("heldout.compare", "aligned")),
])
def test_delta_study_file_errors(tmp_path, change, fragments):
    p = _write(tmp_path, DELTA.replace(*change))
    with pytest.raises(InputFileError) as exc:
        load_study(p)
    for f in (str(p),) + fragments:
        assert f in str(exc.value), str(exc.value)
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "out")])
    assert_user_error(r, *fragments)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("change, fragments", [
    (("methods: [auto]", "methods: [{method: auto, machines: [kossel-mini]}]"),
     ("no method fits machine 'stewart-prototype' with setup 'full-pose'",)),
    (("methods: [auto]", "methods: [{method: auto, setups: [tracker]}]"),
     ("methods[0].setups[0]", "'tracker' is not the label of a study setup")),
    (("    setups: [probe]\n", ""), ("setups[2].setup", "machine 'kossel-mini'", "machines[N].setups")),
    (("setups: [probe]", "setups: [probes]"), ("machines[1].setups[0]", "'probes' is not the label")),
    (("heldout: {poses: 6}", "heldout: {file: held.csv}"), ("one kind of machine", "heldout: {poses: N}")),
    (("heldout: {poses: 6}", "heldout: {poses: 6, compare: sensor}"),
     ("machine 'planar-3dof-4act' settles at static equilibrium", "leave 'compare' out")),
])
def test_mixed_study_file_errors(tmp_path, change, fragments):
    (tmp_path / "held.csv").write_text("x,y,z,a,b,c\n0,0,450,0,0,0\n", encoding="utf-8")
    p = _write(tmp_path, MIXED.replace(*change))
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "out")])
    assert_user_error(r, str(p), *fragments)


def test_examples_of_other_machines_load():
    from pathlib import Path

    examples = Path(__file__).resolve().parents[2] / "examples"
    kinds = {}
    for name in ("study-delta-printer.yaml", "study-planar.yaml"):
        s = load_study(examples / name)
        kinds[name] = {m.nominal.kind for m in s.machines}
        assert not math.isnan(s.trials)
    assert kinds == {"study-delta-printer.yaml": {"linear-delta"},
                     "study-planar.yaml": {"planar-3dof-4act", "planar-2dof-3act"}}


def test_progress_estimate_uses_the_reading_where_a_row_has_no_position():
    """The bar's running median takes a row's position error, or its reading error when it
    is compared on readings (dial indicators, a Z probe)."""
    from pkmcal.study.results import column_names
    from pkmcal.study.runner import _Progress

    names = column_names()
    bar = _Progress(total=2, done=0, enabled=True, names=names)
    rows = [dict.fromkeys(names, "") for _ in range(2)]
    rows[0]["heldout_position_rms_mm"] = "0.25"
    rows[1]["heldout_reading_rms_mm"] = "0.015"
    try:
        bar.update(2, [",".join(r[n] for n in names) for r in rows])
    finally:
        bar.close()
    assert bar.values == [0.25, 0.015]


# -- paper 3's baselines -------------------------------------------------------------------------

BASELINE_STUDY = PLANAR.replace("methods: [auto]", "methods: [auto, ignore-redundancy, actuator-subset]").replace(
    "  - nominal: planar-2dof-3act\n    errors:\n      - {parameters: \"[lBD]*\", distribution: uniform, size: 0.5}\n"
    "      - {parameters: \"dq*\", distribution: uniform, size: 0.1}\n", "")


def test_paper3_baselines_in_a_study(tmp_path):
    """Paper 3 §1's ways of calibrating a redundant machine as if it were not (the encoders
    replaced by the commands; a non-redundant subset of the actuators) as study methods: the
    projection method lands the tool closer than either, on the same simulated machines."""
    study = load_study(_write(tmp_path, BASELINE_STUDY))
    assert [m.nominal.name for m in study.machines] == ["planar-3dof-4act"]
    run_study(study, tmp_path / "r", workers=1, figures=False)
    cols = read_trials(tmp_path / "r" / "trials.csv")
    assert np.all(cols["failed"] == 0), cols["message"]
    assert list(cols["identification"][::3]) == ["projection", "ignore-redundancy", "actuator-subset"]
    err = {m: cols["heldout_position_rms_mm"][cols["method"] == m] for m in ("auto", "ignore-redundancy",
                                                                              "actuator-subset")}
    assert np.all(err["auto"] < err["ignore-redundancy"]) and np.all(err["auto"] < err["actuator-subset"]), err


def test_a_baseline_trial_is_what_identify_and_verify_make_of_it(tmp_path):
    """Trial 1 of the ignore-redundancy configuration through the commands, as the planar
    projection trial above: `pkmcal identify --method ignore-redundancy` and `pkmcal verify`."""
    study = load_study(_write(tmp_path, BASELINE_STUDY))
    row, fit, ver = trial_through_commands(tmp_path, study, 1,
                                      ["--setup", "planar-tracker", "--method", "ignore-redundancy"],
                                      ["--setup", "planar-tracker"])
    assert row["identification"] == "ignore-redundancy"
    assert fit["method"] == "ignore-redundancy"
    assert float(row["chi2"]) == pytest.approx(fit["chi2"], rel=1e-8)
    assert float(row["heldout_position_rms_mm"]) == pytest.approx(ver["after"]["tool_rms_mm"], rel=1e-6)
    assert float(row["heldout_position_rms_before_mm"]) == pytest.approx(ver["before"]["tool_rms_mm"], rel=1e-6)


def test_a_baseline_on_a_machine_that_is_not_redundant_is_refused(tmp_path):
    p = _write(tmp_path, MIXED.replace("methods: [auto]", "methods: [auto, ignore-redundancy]"))
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "out")])
    assert_user_error(r, str(p), "'ignore-redundancy'", "paper 3 baseline", "machine 'stewart-prototype'",
                      "machines: [...]")
