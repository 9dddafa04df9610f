"""No calibrated file from a fit that is plainly wrong (issue 24 item 1).

Each test names the old behaviour it fails on. One simulated full-pose campaign of the
prototype (30 random poses, paper 1's noise) is written in the forms a user's instrument
might give it: Euler angles in degrees (right), rotation vectors in radians read as degrees,
scalar-first quaternions read scalar-last. The refusal rule is checked against scipy's χ²
quantile (:mod:`pkmcal.identification.fit_verdict`).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from scipy.spatial.transform import Rotation
from scipy.stats import chi2 as chi2_dist

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.fit_verdict import NOISE_SLACK, TAIL, beyond_noise, judge
from pkmcal.identification.priors import check_plausible, resolve
from pkmcal.identification.uncertainty import Uncertainty
from pkmcal.io.lookup import load_machine
from pkmcal.io.tables import format_table, read_table

LEGS = [f"lambda{i}" for i in range(1, 7)]


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    """The campaign's measurement files: ``degrees`` as pkmcal writes it, ``rotvec_rad`` and
    ``quat_wxyz`` the same orientations as rotation vectors in radians (no units line) and
    as scalar-first quaternions in positional columns q1..q4 (no --quaternion-order)."""
    d = tmp_path_factory.mktemp("campaign")
    rng = np.random.default_rng(11)
    half = np.array([8.0, 8.0, 4.0, 6.0, 6.0, 8.0])
    poses = rng.uniform(-1, 1, (30, 6)) * half + np.r_[0.0, 0.0, 312.0, 0.0, 0.0, 0.0]
    (d / "poses.csv").write_text(format_table({k: poses[:, i] for i, k in enumerate("xyzabc")}))
    ok(run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "full-pose-paper1",
           "--poses", d / "poses.csv", "--seed", 3, "-o", d / "degrees.csv"))
    t = read_table(d / "degrees.csv", LEGS + list("xyzabc"))
    rot = Rotation.from_euler("xyz", np.deg2rad(t[["a", "b", "c"]]))
    base = {k: t[k] for k in LEGS + ["x", "y", "z"]}
    rv = rot.as_rotvec()
    (d / "rotvec_rad.csv").write_text(format_table({**base, "rx": rv[:, 0], "ry": rv[:, 1], "rz": rv[:, 2]}))
    q = rot.as_quat()                                    # x, y, z, w
    wxyz = np.c_[q[:, 3], q[:, :3]]
    (d / "quat_wxyz.csv").write_text(format_table({**base, **{f"q{i + 1}": wxyz[:, i] for i in range(4)}}))
    return d


def identify(d, meas, *extra, name="cal.yaml"):
    return run("identify", "stewart-prototype", meas, "--setup", "full-pose-paper1", "-o", d / name, *extra)


def test_the_right_file_is_written_with_an_acceptable_verdict(campaign):
    res = ok(identify(campaign, campaign / "degrees.csv", "--json"))
    d = json.loads(res.stdout)
    assert d["verdict"]["acceptable"] and not d["verdict"]["problems"]
    assert "looks like radians" not in res.stderr and "scalar-first" not in res.stderr


def test_radian_rotation_vectors_read_as_degrees_are_refused(campaign):
    """Old behaviour: χ²/ν 829 and a calibrated file written, with warnings only."""
    res = identify(campaign, campaign / "rotvec_rad.csv", name="bad.yaml")
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert "refused" in res.stderr and "--angle-unit rad" in res.stderr and "nothing written" in res.stderr
    assert not (campaign / "bad.yaml").exists()
    # stated, the same file calibrates
    ok(identify(campaign, campaign / "rotvec_rad.csv", "--angle-unit", "rad", name="rad-ok.yaml"))


def test_scalar_first_quaternions_are_refused_naming_the_order(campaign):
    """Old behaviour: χ²/ν 2.4e5; refused only because a leg offset came out at 855 km."""
    res = identify(campaign, campaign / "quat_wxyz.csv", name="bad.yaml")
    assert res.exit_code == 2 and "refused" in res.stderr and "--quaternion-order wxyz" in res.stderr, res.output
    assert not (campaign / "bad.yaml").exists()
    ok(identify(campaign, campaign / "quat_wxyz.csv", "--quaternion-order", "wxyz", name="q-ok.yaml"))


def test_accept_bad_fit_writes_it_and_the_file_says_so(campaign):
    res = ok(identify(campaign, campaign / "rotvec_rad.csv", "--accept-bad-fit", name="accepted.yaml"))
    assert "written with --accept-bad-fit" in res.output
    record = yaml.safe_load((campaign / "accepted.yaml").read_text())["calibration"]
    accepted = record["accepted_bad_fit"]
    assert any("chi2/E[chi2]" in p for p in accepted["problems"])
    assert any("radians" in c for c in accepted["diagnoses"])


def test_a_prior_in_metres_is_an_error_naming_it(campaign):
    """Old behaviour (a delta's arms): --prior 'arm_*=0.215±0.0001' made the arms 128 mm."""
    res = identify(campaign, campaign / "degrees.csv", "--prior", "L0_2=0.305±0.001", name="bad.yaml")
    # the prototype's L0_2 is 305 mm: 0.305 is it in metres
    assert res.exit_code == 2 and "L0_2" in res.stderr and "metres" in res.stderr, res.output
    assert not (campaign / "bad.yaml").exists()
    delta = load_machine("kossel-mini")
    names, is_angle = tuple(delta.param_names), tuple(delta.param_is_angle)
    with pytest.raises(PkmcalError, match="arm_a.*metres"):
        check_plausible(resolve(["arm_*=0.215±0.0001"], names, is_angle, delta.params), delta.params, is_angle,
                        n_machine=len(names))


def test_a_prior_beyond_any_machine_is_an_error(campaign):
    """Old behaviour: 'b1.z=1e308±1' reported success with an infinite cost and wrote the
    nominal machine as calibrated."""
    res = identify(campaign, campaign / "degrees.csv", "--prior", "b1.z=1e308±1", name="bad.yaml")
    assert res.exit_code == 2 and "b1.z" in res.stderr and "beyond" in res.stderr, res.output
    assert not (campaign / "bad.yaml").exists()


def test_a_prior_the_data_contradict_is_named_with_its_distance(campaign):
    """A plausible value in the right unit, but 300 mm from what the poses say: the fit is
    refused, and the diagnosis (the fit without priors is acceptable) names the prior."""
    res = identify(campaign, campaign / "degrees.csv", "--prior", "L0_1=+100±0.001", name="bad.yaml")
    assert res.exit_code == 2, res.output
    assert "prior on L0_1" in res.stderr and "sigma from what the data say" in res.stderr


def test_a_noise_far_too_small_is_named(campaign, tmp_path):
    setup = tmp_path / "tight.yaml"
    setup.write_text("sensor: full-pose\nnoise: {distribution: uniform, position: 0.0001, orientation_deg: 0.0002, "
                     "actuator: 0.00004}\n")
    res = run("identify", "stewart-prototype", campaign / "degrees.csv", "--setup", setup, "-o", tmp_path / "c.yaml")
    assert res.exit_code == 2 and "refused" in res.stderr, res.output
    assert "noise far too small" in res.stderr


def test_a_noise_somewhat_optimistic_is_written_with_a_warning(campaign, tmp_path):
    """σ stated 1.6 times too small (χ²/ν ≈ 2.5: beyond the 1e-6 tail at ν = 138, within the
    slack of 3): not a wrong fit; written, the covariance inflated, and the warning says so."""
    setup = tmp_path / "optimistic.yaml"
    setup.write_text("sensor: full-pose\nnoise: {distribution: uniform, position: 0.0156, orientation_deg: 0.0358, "
                     "actuator: 0.00625}\n")
    res = ok(run("identify", "stewart-prototype", campaign / "degrees.csv", "--setup", setup,
                 "-o", tmp_path / "c.yaml", "--json"))
    d = json.loads(res.stdout)
    assert d["verdict"]["acceptable"] and 1.6 < d["reduced_chi2"] < 9
    assert any("beyond the 1e-06 tail" in w for w in d["warnings"])


@pytest.mark.parametrize("dof", [3, 40, 138, 5000])
def test_the_refusal_rule_is_the_chi2_tail_with_slack(dof):
    """Independent: the threshold is scipy's χ² quantile at 1 − 1e-6, times NOISE_SLACK²."""
    edge = chi2_dist.isf(TAIL, dof) * NOISE_SLACK**2

    def unc(c):
        return Uncertainty(names=("p",), covariance_prior=np.eye(1), covariance_posterior=np.eye(1), chi2=c, dof=dof)

    assert not beyond_noise(unc(edge * 0.999), NOISE_SLACK)
    assert beyond_noise(unc(edge * 1.001), NOISE_SLACK)


def test_a_fit_that_did_not_converge_or_moved_a_joint_absurdly_is_refused():
    machine = load_machine("stewart-prototype")

    class Result:
        success, message, cost = False, "max_nfev reached", 1.0
        uncertainty = Uncertainty(names=("p",), covariance_prior=np.eye(1), covariance_posterior=np.eye(1),
                                  chi2=10.0, dof=10)
        mechanism, names, param_is_angle = machine, machine.param_names, ()
        initial = estimate = machine.params

    v = judge(Result())
    assert not v.acceptable and v.problems == ("the fit did not converge (max_nfev reached)",)
    Result.success = True
    assert judge(Result()).acceptable
    Result.estimate = machine.params + np.where(np.array(machine.param_names) == "b3.y", 306.0, 0.0)
    v = judge(Result())          # the machine's size is its largest parameter, L0 = 305 mm
    assert not v.acceptable and "b3.y by 306 mm" in v.problems[0]


def test_prior_units_checks_on_angles_and_inches():
    names, is_angle = ("angle_a", "radius_a", "tool.x"), (True, False, False)
    theta0 = np.array([np.deg2rad(210.0), 105.2, 0.0])
    for text, word in (("angle_a=3.665±0.01", "radians"), ("radius_a=4.14±0.01", "inches")):
        with pytest.raises(PkmcalError, match=word):
            check_plausible(resolve([text], names, is_angle, theta0), theta0, is_angle, n_machine=2)
    # a sensor parameter may sit anywhere an instrument can: 2 m from the machine's origin
    check_plausible(resolve(["tool.x=2000±5"], names, is_angle, theta0), theta0, is_angle, n_machine=2)
    with pytest.raises(PkmcalError, match="machine's size"):   # a machine parameter may not
        check_plausible(resolve(["radius_a=2000±5"], names, is_angle, theta0), theta0, is_angle, n_machine=2)


def test_f_scale_without_a_loss_and_absurd_f_scale_are_errors(campaign):
    """Old behaviour: --f-scale without --loss silently ignored; --f-scale 1e308 an
    OverflowError traceback."""
    res = identify(campaign, campaign / "degrees.csv", "--f-scale", "2", name="bad.yaml")
    assert res.exit_code == 2 and "--loss" in res.stderr, res.output
    res = identify(campaign, campaign / "degrees.csv", "--f-scale", "1e308", "--loss", "soft_l1", name="bad.yaml")
    assert res.exit_code == 2 and "f_scale" in res.stderr and res.exception is None or \
        isinstance(res.exception, SystemExit), res.output
    assert not (campaign / "bad.yaml").exists()


@pytest.mark.parametrize("command", ["ik", "plan"])
def test_readers_of_orientations_warn_on_radians_and_scalar_first(campaign, command):
    """Old behaviour: ik and plan --candidates read radian rotation vectors as degrees and
    called the poses reachable, 57 times too small, with no word."""
    def go(f):   # read as scalar-last, the quaternions turn every pose by 180 deg: plan finds none reachable
        if command == "ik":
            return ok(run("ik", "stewart-prototype", "--poses", campaign / f, "-o", campaign / f"legs-{f}"))
        return run("plan", "stewart-prototype", "--setup", "full-pose-paper1", "--candidates", campaign / f,
                   "--n-poses", 20, "-o", campaign / f"plan-{f}")

    assert "--angle-unit rad" in go("rotvec_rad.csv").stderr
    assert "--quaternion-order wxyz" in go("quat_wxyz.csv").stderr
    quiet = go("degrees.csv").stderr
    assert "radians" not in quiet and "scalar-first" not in quiet


def test_a_clipped_policy_that_dropped_most_poses_is_named():
    from pkmcal.identification.fit_verdict import diagnose
    from pkmcal.identification.priors import NO_PRIORS

    machine = load_machine("stewart-prototype")

    class Result:
        priors, dropped, used_poses = NO_PRIORS, np.zeros(0, dtype=int), np.arange(10)
        residuals_weighted, residual_names = np.ones((10, 6)), tuple("xyzabc")
        mechanism, names, param_is_angle = machine, machine.param_names, ()
        initial = estimate = machine.params

    class Meas:
        actuators, notes = np.zeros((10, 6)), ()

    causes = diagnose(Result(), None, Meas(), n_read=30)
    assert any("left out 20 of the 30 poses" in c for c in causes)
    assert not any("left out" in c for c in diagnose(Result(), None, Meas(), n_read=12))


def test_the_python_api_warns_where_the_command_refuses(campaign):
    import pkmcal
    from pkmcal.errors import PkmcalWarning

    machine = pkmcal.load_machine("stewart-prototype")
    setup = pkmcal.load_setup("full-pose-paper1", machine)
    with pytest.warns(PkmcalWarning):                      # the reader's note on the radians
        meas = pkmcal.load_measurements(campaign / "rotvec_rad.csv", machine, setup)
    with pytest.warns(PkmcalWarning, match="would refuse this fit.*--angle-unit rad"):
        result = pkmcal.identify(machine, setup, meas)
    assert not result.verdict.acceptable
