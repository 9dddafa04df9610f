"""Safety margins of a plan (:mod:`pkmcal.planning.margins`): the default a real machine
survives, checked against the machine's own limit report and against the real prototype of
paper 2 (Table 4), which the former default (0.1 mm / 0.1°) drove past its S-joint limit at
18 of the tutorial's 45 poses."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.setup_file import builtin_setup
from pkmcal.io.tables import read_table
from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real
from pkmcal.mechanisms.planar import planar_3dof_4act
from pkmcal.planning.margins import (
    SafetyMargin,
    default_margin,
    planning_checks,
    planning_machine,
    resolve_margin,
)
from pkmcal.planning.plan import plan_poses


def test_default_margin_closed_form():
    m = default_margin(stewart_prototype())
    # prototype: platform joints at 70 mm from the platform origin, shortest leg 305 + 0 mm
    assert m.stroke_mm == 3.0 and m.clearance_mm == 0.1
    assert m.tilt_deg == pytest.approx(math.degrees(math.atan(3 / 70) + math.atan(3 / 305)), rel=1e-12)
    assert m.tilt_deg == pytest.approx(3.02, abs=0.005)          # the figure --help states
    assert default_margin(planar_3dof_4act()) is None
    given = resolve_margin(stewart_prototype(), tilt_deg=5.0)
    assert (given.stroke_mm, given.tilt_deg, given.clearance_mm) == (3.0, 5.0, 0.1) and "tilt" in given.source


def test_planning_machine_keeps_every_margin_by_the_nominal_limit_report():
    """Poses the shrunk machine accepts are inside the nominal limits by at least the margins
    (the nominal machine's own margins, an independent computation)."""
    nominal = stewart_prototype()
    margin = SafetyMargin(2.0, 4.0, 0.05)
    safe = planning_machine(nominal, margin)
    rng = np.random.default_rng(1)
    poses = np.tile(nominal.home_pose, (4000, 1)) + rng.uniform(-1, 1, (4000, 6)) * [40, 40, 20, 0.2, 0.2, 0.6]
    ok = safe.check_limits(poses).ok
    assert 100 < ok.sum() < 3900                         # both verdicts occur
    rep = nominal.check_limits(poses[ok])
    assert rep.margins["stroke"].min() >= 2.0 - 1e-9
    assert rep.margins["u_joint_tilt"].min() >= math.radians(4.0) - 1e-12
    assert rep.margins["s_joint_tilt"].min() >= math.radians(4.0) - 1e-12
    assert rep.margins["leg_collision"].min() >= 0.05 - 1e-9
    # and the nominal check with one margin of that size agrees where both apply
    assert nominal.check_limits(poses[ok], margin=0.05).ok.all()
    with pytest.raises(PkmcalError, match="leaves no stroke"):
        planning_machine(nominal, SafetyMargin(25.0, 1.0, 0.1))
    with pytest.raises(PkmcalError, match="s joint tilt"):
        planning_machine(nominal, SafetyMargin(1.0, 29.0, 0.1))


@pytest.mark.parametrize("setup_name,seed", [("indicators-prototype", 1), ("indicators-prototype", 2),
                                             ("full-pose-paper1", 1)])
def test_default_plan_is_reached_by_the_real_prototype(setup_name, seed):
    """The tutorial's case: plan on the nominal prototype, command the real one (Table 4):
    every pose is reached and within the real machine's limits."""
    nominal, real, setup = stewart_prototype(), stewart_prototype_real(), builtin_setup(setup_name)
    plan = plan_poses(nominal, setup, 45, seed=seed)
    sim = simulate_campaign(nominal, real, setup, plan.poses, rng=2)
    assert sim.dropped == {} and len(sim.kept) == 45
    assert isinstance(plan.margin, SafetyMargin) and "3 mm" in plan.describe_margin()
    # the former default drops poses on the S-joint tilt: the test would fail on the old code
    old = plan_poses(nominal, setup, 45, seed=seed, margin=0.1)
    dropped = simulate_campaign(nominal, real, setup, old.poses, rng=2).dropped
    if setup_name == "indicators-prototype":
        assert any("s_joint_tilt" in why for why in dropped.values())


def test_plan_command_states_and_uses_its_margin(tmp_path):
    runner = CliRunner()
    out = tmp_path / "p.csv"
    args = ["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n", "15", "--n-candidates", "300"]
    res = runner.invoke(cli, [*args, "--tilt-margin", "5", "-o", str(out), "--units-comment"])
    assert res.exit_code == 0, res.output
    assert "safety margin: stroke 3 mm, joint tilts 5 deg, leg clearance 0.1 mm (given: tilt; others default)" \
        in res.stdout
    assert "# safety margin: stroke 3 mm, joint tilts 5 deg" in out.read_text()
    assert out.read_bytes().isascii()                  # spreadsheet programs read it with any code page
    names = ["x", "y", "z", "a", "b", "c"]
    poses = read_table(out, names)[names].copy()
    poses[:, 3:] = np.deg2rad(poses[:, 3:])
    rep = stewart_prototype().check_limits(poses)
    assert rep.margins["s_joint_tilt"].min() >= math.radians(5.0) - 1e-9
    assert rep.margins["stroke"].min() >= 3.0 - 1e-9
    res = runner.invoke(cli, [*args, "--margin", "1", "--tilt-margin", "2", "-o", str(out)])
    assert res.exit_code == 2 and "not both" in res.stderr
    res = runner.invoke(cli, ["plan", "planar-3dof-4act", "--setup", "planar-tracker", "--n", "8",
                              "--tilt-margin", "2", "-o", str(tmp_path / "q.csv")])
    assert res.exit_code == 2 and "no stroke or joint-tilt limits" in res.stderr
    res = runner.invoke(cli, ["plan", "--help"], terminal_width=200)
    tilt = default_margin(stewart_prototype()).tilt_deg
    assert f"({tilt:.3g}° on stewart-prototype)" in res.output


# -- deltas -----------------------------------------------------------------------------------

_LEVER = {"angle": "radius", "zero": "upper", "axis_yaw": "upper", "axis_tilt": "upper", "lean_radial": "endstop",
          "lean_tangential": "endstop"}


def _perturbed_delta(m, rng, d=3.0):
    """``m`` with every length off by up to d mm and every angle by up to d over its lever."""
    p = m.params.copy()
    val = dict(zip(m.param_names, m.params))
    for i, name in enumerate(m.param_names):
        base, tower = name.rsplit("_", 1) if "_" in name else (name, "")
        if base in ("radius", "arm", "endstop", "height", "upper", "forearm"):
            p[i] += rng.uniform(-d, d)
        elif base in _LEVER:
            p[i] += rng.uniform(-d, d) / val[f"{_LEVER[base]}_{tower}"]
    return m.with_params(p, name=m.name + "-real")


def test_delta_margins_closed_form_and_printed():
    from pkmcal.io.machine_file import load_machine
    from pkmcal.planning.margins import DeltaSafetyMargin

    k = default_margin(load_machine("kossel-mini"))
    assert isinstance(k, DeltaSafetyMargin)
    assert (k.travel, k.space_mm) == (3.0, 6.0)
    assert k.angle_deg == pytest.approx(math.degrees(math.atan(3 / 215)), rel=1e-12)
    assert k.describe().startswith("rail travel 3 mm, arm angle 0.799 deg, print radius and bed 6 mm")
    r = default_margin(load_machine("delta-picker"))
    assert (r.travel, r.angle_deg, r.space_mm) == pytest.approx(
        (math.degrees(math.atan(3 / 350)), math.degrees(math.atan(3 / 800)), 9.0), rel=1e-12)
    with pytest.raises(PkmcalError, match="--margin"):
        resolve_margin(load_machine("kossel-mini"), stroke_mm=1.0)
    out = CliRunner().invoke(cli, ["plan", "kossel-mini", "--setup", "laser-tracker", "--n", "12"])
    assert out.exit_code == 0, out.output
    assert "safety margin: rail travel 3 mm, arm angle 0.799 deg" in out.output


@pytest.mark.parametrize("name", ["kossel-mini", "delta-picker"])
def test_default_delta_plan_is_reached_by_a_perturbed_delta(name):
    """Plan on the nominal delta, command one with 3 mm joint errors: every pose is reached
    within its limits; the same plan without margins is not (the test can fail)."""
    from pkmcal.io.machine_file import load_machine

    nominal, setup = load_machine(name), builtin_setup("laser-tracker")
    plan = plan_poses(nominal, setup, 30, seed=1)
    bare = plan_poses(nominal, setup, 30, seed=1, margin=0.0)
    lost = 0
    for k in range(4):
        real = _perturbed_delta(nominal, np.random.default_rng(k))
        assert simulate_campaign(nominal, real, setup, plan.poses, rng=2).dropped == {}
        lost += len(simulate_campaign(nominal, real, setup, bare.poses, rng=2).dropped)
    assert lost > 0
    # the margins hold on the nominal machine: every planned pose is that far inside
    safe, check = planning_checks(nominal, plan.margin)
    assert safe.check_limits(plan.poses, margin=check).ok.all()
