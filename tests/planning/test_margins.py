"""Safety margins of a plan (:mod:`pkmcal.planning.margins`): the default a real machine
survives, checked against the machine's own limit report and against the real prototype of
paper 2 (Table 4), which the former default (0.1 mm / 0.1°) drove past its S-joint limit at
18 of the tutorial's 45 poses."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import (
    LINUXCNC_SAMPLE_BASE_IN,
    LINUXCNC_SAMPLE_HOME_IN,
    LINUXCNC_SAMPLE_PLATFORM_IN,
    write_linuxcnc_hexapod_sample,
)

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io.import_linuxcnc import machine_from_linuxcnc
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
    args = ["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n-poses", "15", "--n-candidates", "300"]
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
    res = runner.invoke(cli, ["plan", "planar-3dof-4act", "--setup", "planar-tracker", "--n-poses", "8",
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
    out = CliRunner().invoke(cli, ["plan", "kossel-mini", "--setup", "laser-tracker", "--n-poses", "12"])
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


# -- a controller's configuration with limits far beyond the machine (issue 24 item 5) ---------

#: Where Debian's linuxcnc-uspace installs LinuxCNC's hexapod sample.
DEBIAN_SAMPLE = Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/hexapod-sim")
INCH = 25.4


def _sample_geometry():
    """The sample's joints (mm) and strut lengths at home, from the typed-in values alone."""
    base = np.array(LINUXCNC_SAMPLE_BASE_IN) * INCH
    platform = np.array(LINUXCNC_SAMPLE_PLATFORM_IN) * INCH
    home_struts = np.linalg.norm(np.array(LINUXCNC_SAMPLE_HOME_IN) * INCH + platform - base, axis=1)
    return base, platform, home_struts


def _rotation(a, b, c):
    """Rz(c) Ry(b) Rx(a) written out here (genhexkins' pmRpyMatConvert), radians."""
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    return np.array([[cc * cb, cc * sb * sa - sc * ca, cc * sb * ca + sc * sa],
                     [sc * cb, sc * sb * sa + cc * ca, sc * sb * ca - cc * sa],
                     [-sb, cb * sa, cb * ca]])


def _assert_within_the_geometry(poses_deg, stroke_mm, tilt_deg):
    """Each pose (x, y, z mm; a, b, c deg) has its angles within the Euler angles' range
    and, by our own kinematics of the sample, every strut within [L_h / 2, 2 L_h] by
    ``stroke_mm`` and every leg within 90° − ``tilt_deg`` of the base and platform normals
    (the bounds of pkmcal.mechanisms.hexapod_reach)."""
    base, platform, home_struts = _sample_geometry()
    assert np.all(np.abs(poses_deg[:, [3, 5]]) <= 180.0) and np.all(np.abs(poses_deg[:, 4]) <= 90.0)
    tol = 1e-9 * 2 * home_struts.max()                  # round-off of lengths ~1.5 m
    for x, y, z, a, b, c in poses_deg:
        R = _rotation(*np.deg2rad([a, b, c]))
        legs = np.array([x, y, z]) + platform @ R.T - base
        L = np.linalg.norm(legs, axis=1)
        assert np.all(L >= home_struts / 2 + stroke_mm - tol) and np.all(L <= 2 * home_struts - stroke_mm + tol)
        u = legs / L[:, None]
        sin_t = math.sin(math.radians(tilt_deg))
        assert np.all(u[:, 2] >= sin_t - 1e-12)            # U joints: within 90° - tilt of the base normal
        assert np.all(u @ R[:, 2] >= sin_t - 1e-12)        # S joints: of the platform normal


def _import_sample(runner, hal, ini, out):
    res = runner.invoke(cli, ["import", "linuxcnc", str(hal), str(ini), "-o", str(out)])
    assert res.exit_code == 0, res.output
    return res


def _default_tilt_deg():
    """The default tilt margin on the sample, from the typed-in values: atan(3/r_p) +
    atan(3/L_min), L_min = half the shortest strut at home (the strut range allowed)."""
    _, platform, home_struts = _sample_geometry()
    r_p = np.linalg.norm(platform, axis=1).min()
    return math.degrees(math.atan(3 / r_p) + math.atan(3 / (home_struts.min() / 2)))


@pytest.mark.parametrize("options,stroke,tilt", [
    ([], 3.0, None), (["--stroke-margin", "3", "--tilt-margin", "3"], 3.0, 3.0), (["--stroke-margin", "2"], 2.0, None),
    (["--tilt-margin", "2"], 3.0, 2.0), (["--margin", "3"], 3.0, 3.0)])
def test_linuxcnc_sample_plans_inside_its_geometry_with_every_margin_option(tmp_path, options, stroke, tilt):
    """LinuxCNC's hexapod sample allows struts of ±1000 inch: ``plan`` used to refuse every
    option but --margin ("give --stroke-margin and --tilt-margin", then the same with both)
    and with --margin 3 planned x = 3938 mm, a = -9450 deg on this 673 mm machine. Every
    option now plans, inside what the geometry reaches, and the note names the loose limit."""
    runner = CliRunner()
    hal, ini = write_linuxcnc_hexapod_sample(tmp_path / "cfg")
    machine = tmp_path / "hexapod.yaml"
    _import_sample(runner, hal, ini, machine)
    out = tmp_path / "p.csv"
    res = runner.invoke(cli, ["plan", str(machine), "--setup", "full-pose-paper1", "--n-poses", "8", "--n-candidates", "300",
                              "--seed", "3", *options, "--units-comment", "-o", str(out)])
    assert res.exit_code == 0, res.output
    names = ["x", "y", "z", "a", "b", "c"]
    poses = read_table(out, names, kinds={})[names]
    _assert_within_the_geometry(poses, stroke, _default_tilt_deg() if tilt is None else tilt)
    assert f"[JOINT_N] MIN_LIMIT/MAX_LIMIT of {ini}" in res.output and "-25400 to 25400 mm" in res.output
    assert "(377.8 to 1511 mm)" in res.output                 # L_h / 2 and 2 L_h, L_h = 755.6 mm
    assert "joint tilt limits beyond 90°" in res.output
    assert f"workspace box ([AXIS_X..C] MIN_LIMIT/MAX_LIMIT of {ini}) is mostly beyond" in res.output
    assert "# note: the strut range of legs 1, 2, 3, 4, 5, 6" in out.read_text()   # the file records it


def test_linuxcnc_sample_planning_box_is_mostly_reachable(tmp_path):
    """The box planning draws from lies within what the geometry reaches: by our own
    kinematics, a good part of uniform poses in it are poses of the machine, where in the box
    of the configured limits (the former one) almost none are."""
    hal, ini = write_linuxcnc_hexapod_sample(tmp_path)
    machine = machine_from_linuxcnc(hal, ini).machine
    plan = plan_poses(machine, builtin_setup("full-pose-paper1"), 8, n_candidates=300, seed=1, margin=3.0)
    assert len(plan.notes) == 3 and "[JOINT_N] MIN_LIMIT/MAX_LIMIT" in plan.notes[0]
    assert f"workspace box ([AXIS_X..C] MIN_LIMIT/MAX_LIMIT of {ini}) is mostly beyond" in plan.notes[2]
    base, platform, home_struts = _sample_geometry()
    rng = np.random.default_rng(0)

    def reachable_fraction(box):
        poses = box[:, 0] + rng.random((4000, 6)) * (box[:, 1] - box[:, 0])
        R = np.array([_rotation(*p[3:]) for p in poses])
        legs = poses[:, None, :3] + np.einsum("nrc,ic->nir", R, platform) - base
        L = np.linalg.norm(legs, axis=2)
        u = legs / L[..., None]
        ok = ((L >= home_struts / 2) & (L <= 2 * home_struts) & (u[..., 2] > 0)
              & (np.einsum("nir,nr->ni", u, R[:, :, 2]) > 0)).all(axis=1)
        return ok.mean()

    new, former = reachable_fraction(plan.box), reachable_fraction(machine.workspace_box())
    assert np.all(np.abs(plan.box[3:]) <= np.array([[np.pi], [np.pi / 2], [np.pi]]))
    assert new > 0.05 > 0.005 > former, (new, former)


def test_debian_linuxcnc_sample_plans_inside_its_geometry(tmp_path):
    """The same on LinuxCNC's own files, where Debian's linuxcnc-uspace installed them."""
    import gzip

    files = {}
    for name in ("kinematics.hal", "hexapod.ini"):
        for candidate in (DEBIAN_SAMPLE / name, DEBIAN_SAMPLE / f"{name}.gz"):
            if candidate.is_file():
                files[name] = candidate
    if len(files) < 2:
        pytest.skip(f"LinuxCNC's hexapod sample is not installed ({DEBIAN_SAMPLE}: Debian's linuxcnc-uspace)")
    for name, path in files.items():                   # read as they are, gunzipped when compressed
        data = gzip.decompress(path.read_bytes()) if path.suffix == ".gz" else path.read_bytes()
        (tmp_path / name).write_bytes(data)
    runner = CliRunner()
    machine = tmp_path / "hexapod.yaml"
    res = _import_sample(runner, tmp_path / "kinematics.hal", tmp_path / "hexapod.ini", machine)
    assert "-25400 to 25400 mm" in res.output
    out = tmp_path / "p.csv"
    res = runner.invoke(cli, ["plan", str(machine), "--setup", "full-pose-paper1", "--n-poses", "8", "--n-candidates",
                              "300", "--margin", "3", "-o", str(out)])
    assert res.exit_code == 0, res.output
    names = ["x", "y", "z", "a", "b", "c"]
    _assert_within_the_geometry(read_table(out, names, kinds={})[names], 3.0, 3.0)
    assert "[JOINT_N] MIN_LIMIT/MAX_LIMIT" in res.output


def test_info_reports_the_sample_workspace_within_its_geometry(tmp_path):
    """``pkmcal info`` on the sample: the single-axis ranges from home are those of the
    machine within its geometry (x within ±2 L_h, where the configured struts reached
    4.4 m), with the notes naming the loose limits."""
    runner = CliRunner()
    hal, ini = write_linuxcnc_hexapod_sample(tmp_path / "cfg")
    machine = tmp_path / "hexapod.yaml"
    _import_sample(runner, hal, ini, machine)
    res = runner.invoke(cli, ["info", str(machine), "--n-poses", "20"])
    assert res.exit_code == 0, res.output
    assert "note: the strut range of legs 1, 2, 3, 4, 5, 6 (-25400 to 25400 mm" in res.output
    _, _, home_struts = _sample_geometry()
    x_line = next(line for line in res.output.splitlines() if line.startswith("  x "))
    lo, hi = (float(v) for v in x_line.split()[1:4:2])
    assert -2 * home_struts.max() < lo < 0 < hi < 2 * home_struts.max(), x_line
