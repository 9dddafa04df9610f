"""pkmcal study: study files, determinism across backends and batching, resume, the
truth in the fit's gauge, coverage, and the summary statistics against independent
formulas (scipy.stats)."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error
from helpers import write_study as _write
from scipy import stats

from pkmcal.cli.main import cli
from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.identification.engine import identify
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.setup_file import builtin_setup
from pkmcal.mechanisms import builtin_machine
from pkmcal.study import backends, load_study, read_trials, run_study
from pkmcal.study.results import median_interval, t_interval, wilson_interval
from pkmcal.study.schema import ErrorGroup, MachineSpec, MethodSpec, PlanSpec, SetupSpec, Study, scaled_noise
from pkmcal.identification.verification import pose_errors
from pkmcal.study.trial import heldout_columns, pseudo_truth

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
SMALL = """\
name: small
seed: 3
trials: 4
machines:
  - nominal: stewart-prototype
    errors:
      - {parameters: "*", distribution: uniform, size: 0.3}
    ignore_limits: [leg_collision]
setups:
  - {setup: full-pose-paper1, label: full-pose}
plans:
  - {algorithm: corners, poses: [12, 15]}
methods: [auto]
heldout: {poses: 6}
"""


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    return load_study(_write(tmp_path_factory.mktemp("s"), SMALL))


@pytest.fixture(scope="module")
def reference(small_study, tmp_path_factory):
    """The small study run in this process: the bytes every other backend must give."""
    out = tmp_path_factory.mktemp("ref") / "r"
    run_study(small_study, out, workers=1, figures=False)
    return out


# -- the study file ------------------------------------------------------------------------


def test_study_file_resolves(small_study):
    s = small_study
    assert s.trials == 4 and s.seed == 3 and len(s.machines) == 1
    assert s.machines[0].errors == (ErrorGroup("*", "uniform", 0.3),)
    assert s.plans[0].resample == "trial"          # corners: a new draw in every trial
    assert s.methods[0].resolved(s.setups[0].setup, s.machines[0].nominal) == "ik-residual"


@pytest.mark.parametrize("change, fragments", [
    (("trials: 4", "trials: 4\nbogus: 1"), ("bogus", "line 4", "not a study key")),
    (("methods: [auto]", "methods: [nonsense]"), ("methods[0]", "unknown method")),
    (("{parameters: \"*\"", "{parameters: \"q*\""), ("matches no parameter",)),
    (("    ignore_limits", "    real: stewart-prototype-real\n    ignore_limits"), ("exactly one of 'errors'",)),
    (("poses: [12, 15]", "poses: [12, 12]"), ("distinct pose counts",)),
    (("algorithm: corners", "algorithm: magic"), ("unknown algorithm",)),
])
def test_study_file_errors_name_the_key(tmp_path, change, fragments):
    p = _write(tmp_path, SMALL.replace(*change))
    with pytest.raises(InputFileError) as exc:
        load_study(p)
    msg = str(exc.value)
    assert str(p) in msg
    for f in fragments:
        assert f in msg, msg


def test_overlapping_error_groups_are_refused(tmp_path):
    p = _write(tmp_path, SMALL.replace('- {parameters: "*", distribution: uniform, size: 0.3}',
                                       '- {parameters: "*", distribution: uniform, size: 0.3}\n'
                                       '      - {parameters: "b1.x", distribution: normal, size: 0.1}'))
    with pytest.raises(InputFileError, match="already in group 1"):
        load_study(p)


def test_noise_scale_multiplies_the_setup_noise():
    base = builtin_setup("indicators-prototype")
    s = scaled_noise(base, 2.0, 0.0)
    assert np.array_equal(s.noise.reading_std, 2.0 * base.noise.reading_std)
    assert np.all(np.asarray(s.noise.actuator_std) == 0.0)


# -- determinism -------------------------------------------------------------------------------


def test_same_bits_with_a_process_pool_and_other_batches(small_study, reference, tmp_path, monkeypatch):
    ref = (reference / "trials.csv").read_bytes()
    run_study(small_study, tmp_path / "pool", workers=2, figures=False)
    assert (tmp_path / "pool" / "trials.csv").read_bytes() == ref
    assert (tmp_path / "pool" / "summary.csv").read_bytes() == (reference / "summary.csv").read_bytes()
    monkeypatch.setattr(backends, "TARGET_SECONDS", 1e-9)     # one trial per batch
    run_study(small_study, tmp_path / "tiny", workers=1, figures=False)
    assert (tmp_path / "tiny" / "trials.csv").read_bytes() == ref
    assert len(list((tmp_path / "tiny" / "parts").iterdir())) == 8   # 2 campaigns × 4 trials


def test_another_seed_gives_other_numbers(small_study, reference, tmp_path):
    run_study(small_study.with_seed(4), tmp_path / "r", workers=1, figures=False)
    assert (tmp_path / "r" / "trials.csv").read_bytes() != (reference / "trials.csv").read_bytes()


def test_tidy_table(reference, small_study):
    cols = read_trials(reference / "trials.csv")
    assert len(cols["trial"]) == 2 * 4
    assert list(cols["config"]) == [0, 0, 0, 0, 1, 1, 1, 1] and list(cols["trial"]) == [0, 1, 2, 3] * 2
    assert set(cols["n_poses"]) == {12, 15}
    ok = cols["failed"] == 0
    assert ok.all(), cols["message"]
    assert np.all(cols["n_free"][ok] == 42) and np.all(cols["rank"][ok] == 42)
    assert np.all(cols["truth_refit"][ok] == 0)       # all 42 free: θ* = θ_real
    # the reported error is θ̂ − θ_real exactly when nothing is fixed
    assert np.array_equal(cols["param_error_mean_abs_mm"], cols["param_error_vs_real_mean_abs_mm"])
    assert np.all(cols["heldout_position_rms_mm"] < cols["heldout_position_rms_before_mm"])
    man = json.loads((reference / "manifest.json").read_text())
    assert man["complete"] is True and man["fingerprint"] == small_study.fingerprint()


# -- resume and the results folder ---------------------------------------------------------------


def test_interrupted_study_resumes_to_the_same_bits(small_study, reference, tmp_path, monkeypatch):
    out = tmp_path / "r"
    real_run_batch = backends.run_batch
    calls = []

    def flaky(*args):
        calls.append(args)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real_run_batch(*args)

    monkeypatch.setattr(backends, "TARGET_SECONDS", 1e-9)
    monkeypatch.setattr(backends, "run_batch", flaky)
    with pytest.raises(PkmcalError, match="--resume"):
        run_study(small_study, out, workers=1, figures=False)
    man = json.loads((out / "manifest.json").read_text())
    assert man["complete"] is False and not (out / "trials.csv").exists()   # never mistaken for finished
    n_parts = len(list((out / "parts").iterdir()))
    assert 0 < n_parts < 8
    with pytest.raises(PkmcalError, match="already holds an unfinished study"):
        run_study(small_study, out, workers=1, figures=False)
    with pytest.raises(PkmcalError, match="different study or seed"):
        run_study(small_study.with_seed(9), out, workers=1, resume=True, figures=False)
    monkeypatch.setattr(backends, "run_batch", real_run_batch)
    res = run_study(small_study, out, workers=1, resume=True, figures=False)
    assert res.trials_run == 8 - n_parts
    assert (out / "trials.csv").read_bytes() == (reference / "trials.csv").read_bytes()
    assert json.loads((out / "manifest.json").read_text())["complete"] is True


def test_resume_extends_a_finished_study(small_study, reference, tmp_path):
    out = tmp_path / "r"
    shutil.copytree(reference, out)
    real_run_batch = backends.run_batch

    def check_not_finished(*args):     # while it runs, the folder must not look finished
        assert not (out / "trials.csv").exists()
        assert json.loads((out / "manifest.json").read_text())["complete"] is False
        return real_run_batch(*args)

    backends.run_batch = check_not_finished
    try:
        res = run_study(small_study.with_trials(6), out, workers=1, resume=True, figures=False)
    finally:
        backends.run_batch = real_run_batch
    assert res.trials_run == 2 * 2
    lines = (out / "trials.csv").read_text().splitlines()
    ref = (reference / "trials.csv").read_text().splitlines()
    assert lines[0] == ref[0] and len(lines) == 1 + 2 * 6
    assert lines[1:5] == ref[1:5] and lines[7:11] == ref[5:9]     # trials 0-3 unchanged, in order


def test_output_folder_is_never_overwritten(small_study, reference, tmp_path):
    (tmp_path / "busy").mkdir()
    (tmp_path / "busy" / "x.txt").write_text("mine")
    with pytest.raises(PkmcalError, match="not empty"):
        run_study(small_study, tmp_path / "busy", workers=1, figures=False)
    with pytest.raises(PkmcalError, match="finished study"):
        run_study(small_study, reference, workers=1, figures=False)


# -- the truth in the fit's gauge, and coverage ---------------------------------------------------


def test_truth_is_the_real_machine_in_the_fits_gauge():
    """Table 4 perturbs a2.x, which the indicators' gauge fixes: the estimate cannot reach
    θ_real. θ* (noise-free fit of the same poses) must (a) be what a nearly noise-free fit
    converges to, (b) differ from θ_real, and (c) be the same machine in another gauge: it
    predicts the real machine's indicator readings on poses it was not fitted to."""
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    setup = scaled_noise(builtin_setup("indicators-prototype"), 1e-6, 1e-6)
    rng = np.random.default_rng(5)
    half = np.array([20.0, 20.0, 10.0, *np.deg2rad([8.0, 8.0, 8.0])])
    cmd = nominal.home_pose + rng.uniform(-1, 1, (120, 6)) * half
    sim = simulate_campaign(nominal, real, setup, cmd, rng, ignore_limits=("leg_collision",)).subset(slice(60))
    fit = identify(nominal, setup, sim.measurements, method="fk-residual")
    assert "a2.x" in fit.gauge
    truth_full = np.concatenate([real.params, setup.sensor.params])
    truth, refit, rms = pseudo_truth(fit, truth_full, nominal, setup, sim, "fk-residual", True)
    assert refit and rms < 1e-9
    free = fit.free_index
    assert np.max(np.abs(fit.estimate[free] - truth[free])) < 1e-3          # noise 1e-8 mm: far below
    assert np.max(np.abs(truth[free] - truth_full[free])) > 0.1              # a gauge move of ~1 mm
    other = nominal.home_pose + rng.uniform(-1, 1, (30, 6)) * half
    twin = nominal.with_params(truth[:48])
    q = nominal.ik(other)
    y_real = setup.sensor.predict(real.frame(real.fk(q, guess=other).poses))
    y_twin = setup.sensor.predict(twin.frame(twin.fk(q, guess=other).poses))
    assert np.max(np.abs(y_real - y_twin)) < 1e-8


def test_heldout_columns_are_the_verification_summary():
    """The held-out columns are the numbers of PoseErrors.summary over the poses both
    models reach (to the bit), angles in degrees; none reached is a message."""
    nominal, real = builtin_machine("stewart-prototype"), builtin_machine("stewart-prototype-real")
    rng = np.random.default_rng(2)
    cmd = nominal.home_pose + rng.uniform(-1, 1, (9, 6)) * np.array([20.0, 20.0, 10.0, 0.1, 0.1, 0.1])
    cmd[2, 2] += 400.0                                           # reached by neither model
    before, after = pose_errors(nominal, real, cmd), pose_errors(real, real, cmd)
    common = before.valid & after.valid
    assert 0 < common.sum() < len(cmd)
    got = heldout_columns(after, before)
    a, b = after.summary(common), before.summary(common)
    deg = float(np.rad2deg(1.0))
    assert got["heldout_used"] == int(common.sum())
    assert got["heldout_position_rms_mm"] == a["position_rms_mm"]
    assert got["heldout_position_max_mm"] == a["position_max_mm"]
    assert got["heldout_orientation_rms_deg"] == a["orientation_rms_rad"] * deg
    assert got["heldout_orientation_max_deg"] == a["orientation_max_rad"] * deg
    assert got["heldout_tilt_rms_deg"] == a["tilt_rms_rad"] * deg
    assert got["heldout_height_rms_mm"] == a["height_rms_mm"]
    assert got["heldout_position_rms_before_mm"] == b["position_rms_mm"]
    assert got["heldout_orientation_rms_before_deg"] == b["orientation_rms_rad"] * deg
    assert got["heldout_tilt_rms_before_deg"] == b["tilt_rms_rad"] * deg
    assert got["heldout_height_rms_before_mm"] == b["height_rms_mm"]
    assert got["heldout_position_rms_before_mm"] > 100 * got["heldout_position_rms_mm"]
    none = pose_errors(nominal, real, cmd[2:3])
    assert heldout_columns(none, none) == {"heldout_used": 0, "message": "the real machine reaches none of the "
                                           "held-out poses with both models"}


def test_reported_covariance_covers_the_truth(tmp_path):
    """Paper 1's set-up (all 42 parameters identifiable, GLS): the per-parameter 95 %
    intervals should hold the truth about 95 % of the time, and the joint ellipsoid too."""
    study = load_study(EXAMPLES / "study-paper1.yaml")
    res = run_study(study.with_trials(40), tmp_path / "r", workers=1, figures=False)
    c = res.columns
    assert np.all(c["failed"] == 0) and np.all(c["truth_refit"] == 0)
    frac = float(np.mean(c["coverage_fraction"]))
    assert 0.90 <= frac <= 0.99, frac
    lo, hi = wilson_interval(int(np.sum(c["ellipsoid_within_95"])), 40)
    assert lo <= 0.95 <= hi
    assert 0.7 < float(np.median(c["error_nsigma_rms"])) < 1.3


# -- statistics against independent formulas ----------------------------------------------------------


def test_wilson_interval():
    z = stats.norm.ppf(0.975)
    assert wilson_interval(0, 10) == (0.0, pytest.approx(z * z / (10 + z * z), rel=1e-12))
    for k, n in ((3, 10), (17, 40), (99, 100)):
        lo, hi = wilson_interval(k, n)
        lo2, hi2 = wilson_interval(n - k, n)
        assert lo == pytest.approx(1 - hi2, abs=1e-15) and hi == pytest.approx(1 - lo2, abs=1e-15)
        # the interval's ends are where the score test of p just rejects: |p̂ − p| = z sqrt(p(1−p)/n)
        for p in (lo, hi):
            assert abs(k / n - p) == pytest.approx(z * math.sqrt(p * (1 - p) / n), rel=1e-9)


def test_t_interval_matches_scipy():
    v = np.random.default_rng(1).normal(2.0, 0.5, 25)
    lo, hi = t_interval(v)
    want = stats.t.interval(0.95, len(v) - 1, loc=v.mean(), scale=stats.sem(v))
    assert lo == pytest.approx(want[0], rel=1e-12) and hi == pytest.approx(want[1], rel=1e-12)


def test_median_interval_uses_the_classical_ranks():
    # n = 20: x_(6) .. x_(15) (coverage 95.86 %); n = 5: no 95 % pair exists
    assert median_interval(np.arange(1.0, 21.0)) == (6.0, 15.0)
    assert all(math.isnan(x) for x in median_interval(np.arange(5.0)))
    n = 101
    j = int(median_interval(np.arange(1.0, n + 1))[0])
    assert stats.binom.cdf(j - 1, n, 0.5) <= 0.025 < stats.binom.cdf(j, n, 0.5)


# -- the command ---------------------------------------------------------------------------------------


def test_cli_study(tmp_path):
    p = _write(tmp_path, SMALL.replace("trials: 4", "trials: 2"))
    out = tmp_path / "res"
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(out), "--workers", "1"])
    assert r.exit_code == 0, r.output
    assert "2 configuration(s) x 2 trials" in r.output and "\r" not in r.output   # no progress bar when piped
    for f in ("trials.csv", "summary.csv", "index.html", "figures/coverage.svg", "figures/distributions.png",
              "figures/error-vs-poses.svg"):
        assert (out / f).exists(), f
    page = (out / "index.html").read_text()
    assert "Study small" in page and "<svg" in page
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(out), "--workers", "1"])
    assert_user_error(r, "already holds a finished study", "--resume")
    r = CliRunner().invoke(cli, ["study", str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "x")])
    assert_user_error(r, "does not exist")
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "y"), "-q", "--seed", "1", "--trials", "1",
                                 "--workers", "1", "--no-figures"])
    assert r.exit_code == 0 and r.output == ""
    assert not (tmp_path / "y" / "index.html").exists()


def test_study_from_python_is_the_command(tmp_path):
    """pkmcal.study (the Python API, issue 27) and 'pkmcal study' run the same study: the same
    trial table byte for byte with the same seed and trial overrides."""
    import pkmcal

    p = _write(tmp_path, SMALL)
    run = pkmcal.study(p, tmp_path / "py", seed=5, trials=1, workers=1, figures=False)
    assert run.trials_run == 2                              # 2 configurations x 1 trial
    r = CliRunner().invoke(cli, ["study", str(p), "-o", str(tmp_path / "cli"), "-q", "--seed", "5", "--trials", "1",
                                 "--workers", "1", "--no-figures"])
    assert r.exit_code == 0, r.output
    assert (tmp_path / "py" / "trials.csv").read_bytes() == (tmp_path / "cli" / "trials.csv").read_bytes()
    with pytest.raises(PkmcalError, match="at least 1"):
        pkmcal.study(p, tmp_path / "z", trials=0)


def test_examples_load():
    files = sorted(EXAMPLES.glob("study-*.yaml"))
    assert len(files) >= 3
    for f in files:
        load_study(f)


def test_a_setup_that_cannot_measure_the_machine_is_refused():
    """A study built in Python binds each setup to each machine when it is prepared (other
    machine kinds: tests/study/test_study_kinds.py)."""
    from pkmcal.study.trial import prepare

    planar = builtin_machine("planar-2dof-3act")
    study = Study(name="x", trials=1, machines=(MachineSpec("p", planar, errors=()),),
                  setups=(SetupSpec("s", builtin_setup("laser-tracker")),), plans=(PlanSpec("r", "random", (5,)),),
                  methods=(MethodSpec("auto", "auto"),))
    with pytest.raises(PkmcalError, match="study setup 's': a 'position' sensor cannot measure machine"):
        prepare(study)
