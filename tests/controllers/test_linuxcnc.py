"""The real LinuxCNC runs pkmcal's exports (:mod:`pkmcal.controllers.linuxcnc`).

Three hexapods are calibrated through the command line (plan → simulate → identify) and
exported (``pkmcal export --format linuxcnc -o HAL --ini INI``):

* ``stewart-prototype``, from a simulated dial-indicator campaign (paper 2's set-up) on
  ``stewart-prototype-real``;
* a generated symmetric hexapod (``symmetric:...``), from a simulated full-pose campaign on a
  randomly perturbed copy;
* LinuxCNC's own sample ``configs/sim/axis/vismach/hexapod-sim`` (Debian installs it under
  /usr/share/doc/linuxcnc/examples/sample-configs/; ``LINEAR_UNITS = inch``), imported with
  ``pkmcal import linuxcnc`` (its joint limits of ±1000 in replaced by a real strut range with
  ``--joint-limits``), calibrated the same way, and exported back in inch.

Each export runs in the real LinuxCNC (Debian's linuxcnc-uspace, headless): 20 poses across
the workspace by MDI ``G53 G0`` and 20 by joint jogs. What LinuxCNC does is compared with what
``pkmcal ik`` and ``pkmcal fk`` print for the calibrated machine file:

* world mode: LinuxCNC's joints against ``pkmcal ik``'s l1..l6, to 1e-9 mm (the issue's bar;
  both evaluate ‖p + R a_i − b_i‖, and what is seen is rounding, about 1e-13 mm);
* joint mode: LinuxCNC's pose at the joints it holds after the jogs against ``pkmcal fk`` of
  those joints. Both are iterative and stop on the strut lengths: genhexkins when every strut
  is within its convergence criterion (1e-9 controller units) and pkmcal within 1e-9 mm, so the
  strut residuals r of both poses are checked against those, and the poses must agree to
  2 ‖J⁻¹‖₂ (‖r_LinuxCNC‖₂ + ‖r_pkmcal‖₂) + rounding (J = ∂L/∂pose of the calibrated machine;
  first order, with a factor 2 for the second);
* homing ends at the exported ``[JOINT_N] HOME`` (= pkmcal's strut lengths at the home pose)
  within the stopping tolerance of LinuxCNC's joint planner, ``TINY_DP = 0.001 a T²``
  (LinuxCNC ``src/emc/motion/simple_tp.c``, ``simple_tp_update``: a joint stops once within
  it); jogs stop within twice that of their targets (an incremental jog starts from the
  previous target, not from where the joint stopped).

LinuxCNC not installed: the tests skip with the reason, except in CI (``CI`` set), where they
fail (.ci/run installs it).
"""

from __future__ import annotations

import csv
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import assert_user_error, require_controller

from pkmcal.cli.main import cli
from pkmcal.controllers import linuxcnc as lc
from pkmcal.io import load_machine

SAMPLE = Path("/usr/share/doc/linuxcnc/examples/sample-configs/sim/axis/vismach/hexapod-sim")
SYMMETRIC = "symmetric:base_radius=200,platform_radius=100,offset=300,stroke=100"
N_POSES = 20
EPS = np.finfo(float).eps


def half_unit_mm(u: float) -> float:
    """Half a unit of the last decimal the export writes lengths with in a unit of ``u`` mm
    (export_linuxcnc.LINUXCNC_DECIMALS: 6 in mm, 8 in inch), in mm, plus the decimal
    conversion's round-off of numbers below 1e3 mm."""
    from pkmcal.io.export_linuxcnc import LINUXCNC_DECIMALS

    return 0.5 * 10.0 ** -LINUXCNC_DECIMALS["inch" if u == 25.4 else "mm"] * u + np.spacing(1e3)


def strut_rounding_mm(u: float) -> float:
    """The largest change of a strut length |p + R a − b| when each coordinate of a and b is
    rounded by up to :func:`half_unit_mm`: |Δb| + |Δa| ≤ 2·√3·that (R keeps lengths)."""
    return 2 * np.sqrt(3) * half_unit_mm(u)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


def read_csv(path: Path, columns) -> np.ndarray:
    rows = [r for r in csv.DictReader(line for line in path.read_text().splitlines() if not line.startswith("#"))]
    return np.array([[float(r[c]) for c in columns] for r in rows])


def write_csv(path: Path, columns, values: np.ndarray) -> None:
    lines = [",".join(columns)] + [",".join(repr(float(v)) for v in row) for row in values]
    path.write_text("\n".join(lines) + "\n")


@dataclass
class Case:
    name: str
    folder: Path
    calibrated: Path
    hal: Path
    ini: Path
    check: lc.LinuxcncCheck

    @property
    def machine(self):
        return load_machine(self.calibrated)


def calibrate(d: Path, machine: str, setup: str, real: list[str]) -> Path:
    """plan → simulate → identify through the command line; the calibrated machine file."""
    ok(run("plan", machine, "--setup", setup, "--n-poses", 30, "--seed", 1, "-o", d / "poses.csv"))
    ok(run("simulate", machine, *real, "--setup", setup, "--poses", d / "poses.csv", "--seed", 2,
           "-o", d / "meas.csv"))
    ok(run("identify", machine, d / "meas.csv", "--setup", setup, "-o", d / "calibrated.yaml"))
    return d / "calibrated.yaml"


def make_case(name: str, d: Path) -> Case:
    if name == "stewart-prototype":
        cal = calibrate(d, "stewart-prototype", "indicators-prototype", ["--real", "stewart-prototype-real"])
    elif name == "symmetric":
        cal = calibrate(d, SYMMETRIC, "full-pose-paper1", ["--random-errors", 0.5])
    else:
        ok(run("import", "linuxcnc", SAMPLE / "kinematics.hal", SAMPLE / "hexapod.ini", "--joint-limits", "600,900",
               "-o", d / "imported.yaml"))
        cal = calibrate(d, d / "imported.yaml", "full-pose-paper1", ["--random-errors", 0.5])
    hal, ini = d / "kinematics.hal", d / "joints.ini"
    ok(run("export", cal, "--format", "linuxcnc", "-o", hal, "--ini", ini))
    files = lc.controller_files(hal.read_text(), ini.read_text(), source=str(hal))
    check = lc.check_machine(load_machine(cal), files, n_poses=N_POSES, seed=3)
    return Case(name, d, cal, hal, ini, check)


@pytest.fixture(scope="module", params=["stewart-prototype", "symmetric", "hexapod-sim-inch"])
def case(request, tmp_path_factory):
    require_controller(lc.missing_reason())
    if request.param == "hexapod-sim-inch" and not (SAMPLE / "hexapod.ini").exists():
        require_controller(f"LinuxCNC's sample configuration {SAMPLE} is not installed")
    return make_case(request.param, tmp_path_factory.mktemp(request.param))


def test_world_mode_joints_are_pkmcal_ik(case):
    run_ = case.check.run
    u = run_.mm_per_unit
    assert len(run_.commanded) >= 20
    poses = np.array(run_.commanded, dtype=float)
    poses[:, :3] *= u                                   # what LinuxCNC was told, in mm and degrees
    write_csv(case.folder / "lc-poses.csv", "x y z a b c".split(), poses)
    ok(run("ik", case.calibrated, "--poses", case.folder / "lc-poses.csv", "-o", case.folder / "lc-legs.csv"))
    legs = read_csv(case.folder / "lc-legs.csv", [f"l{i}" for i in range(1, 7)])
    diff = np.abs(run_.joints * u - legs)
    print(f"{case.name}: largest |LinuxCNC joint - pkmcal ik| over {len(poses)} poses: {diff.max():.3g} mm "
          f"(the export's rounding to 1 nm changes the struts by {case.check.rounding:.3g} mm)")
    # the calibrated machine: to 1e-9 plus what the export's rounding changes, which is below
    # its bound; the machine as exported (rounded): to 1e-9 itself
    assert case.check.rounding <= strut_rounding_mm(u)
    assert diff.max() <= 1e-9 + case.check.rounding
    from pkmcal.io.export_linuxcnc import rounded_machine

    exported = rounded_machine(load_machine(case.calibrated), run_.linear_unit)
    assert np.abs(run_.joints * u - exported.leg_lengths(case.check.poses)).max() <= 1e-9
    # how much of the workspace box the poses cover (printed; chosen by workspace_poses)
    span = np.ptp(case.check.poses, axis=0) / np.ptp(case.machine.workspace_box(), axis=1)
    print(f"{case.name}: the poses span {np.array2string(span, precision=2)} of the workspace box")


def test_joint_mode_pose_is_pkmcal_fk_of_the_joints_held(case):
    run_, machine = case.check.run, case.machine
    u = run_.mm_per_unit
    held = run_.joints_held * u
    assert len(held) >= 20
    write_csv(case.folder / "held.csv", [f"l{i}" for i in range(1, 7)], held)
    ok(run("fk", case.calibrated, case.folder / "held.csv", "-o", case.folder / "fk.csv"))
    fk_file = read_csv(case.folder / "fk.csv", "x y z a b c converged same_branch".split())
    assert np.all(fk_file[:, 6:] == 1)
    lc_file = np.array(run_.jog_world, dtype=float)
    lc_file[:, :3] *= u
    from pkmcal.conventions import poses_from_file_units

    lc_pose, fk_pose = poses_from_file_units(lc_file), poses_from_file_units(fk_file[:, :6])
    r_lc = machine.leg_lengths(lc_pose) - held
    r_fk = machine.leg_lengths(fk_pose) - held
    round_off = 64 * EPS * np.max(held)
    # LinuxCNC solves the struts of the machine as exported (rounded to 1 nm): the calibrated
    # machine's residuals there are its convergence criterion plus the rounding's change
    assert np.max(np.abs(r_lc)) <= lc.GENHEXKINS_CONVERGENCE * u + strut_rounding_mm(u) + round_off, \
        np.abs(r_lc).max()
    assert np.max(np.abs(r_fk)) <= 1e-9 + round_off, np.abs(r_fk).max()
    J = np.asarray(machine.gains)[None, :, None] * machine.actuator_pose_jacobian(fk_pose)
    inv_norm = 1.0 / np.linalg.svd(J, compute_uv=False)[:, -1]
    bound = inv_norm * (2 * (np.linalg.norm(r_lc, axis=1) + np.linalg.norm(r_fk, axis=1)) + round_off)
    diff = lc_file - fk_file[:, :6]                      # mm and degrees
    diff[:, 3:] = np.deg2rad(diff[:, 3:])                # radians, the bound's unit for angles
    print(f"{case.name}: largest |LinuxCNC pose - pkmcal fk| over {len(held)} jogs: "
          f"{np.abs(diff[:, :3]).max():.3g} mm, {np.rad2deg(np.abs(diff[:, 3:]).max()):.3g} deg "
          f"(bounds up to {bound.max():.3g}; strut residuals LinuxCNC {np.abs(r_lc).max():.3g}, pkmcal "
          f"{np.abs(r_fk).max():.3g} mm)")
    assert np.all(np.abs(diff) <= bound[:, None])


def test_homing_ends_at_the_exported_home_and_jogs_stop_within_linuxcnc_tolerance(case):
    run_, machine = case.check.run, case.machine
    u = run_.mm_per_unit
    home_l = machine.leg_lengths(machine.home_pose)[0]
    stop = run_.stop_tolerance * u          # TINY_DP of the generated configuration, mm
    assert 0 < stop <= 1e-4
    assert np.max(np.abs(run_.home_joints * u - home_l)) <= stop
    home_traj = np.array([float(v) for v in _ini_value(case.ini, "TRAJ", "HOME").split()])
    # the pose after homing is [TRAJ] HOME, off by what the joints' stopping tolerance moves it:
    # at most ‖J⁻¹‖₂ √6 TINY_DP to first order (twice that allowed)
    J = np.asarray(machine.gains)[:, None] * machine.actuator_pose_jacobian(machine.home_pose[None])[0]
    off = 2 * np.sqrt(6) * stop / np.linalg.svd(J, compute_uv=False)[-1]
    diff = run_.home_world - home_traj
    diff[:3] *= u
    diff[3:] = np.deg2rad(diff[3:])
    assert np.all(np.abs(diff) <= off), (diff, off)
    assert np.max(np.abs(run_.joints_held - run_.jog_targets)) * u <= 2 * stop


def _ini_value(path: Path, section: str, key: str) -> str:
    from pkmcal.io.import_linuxcnc import read_ini

    return read_ini(path).get(section, key)[0]


def test_the_export_is_in_the_units_of_the_machines_ini(case):
    unit = _ini_value(case.ini, "TRAJ", "LINEAR_UNITS")
    assert unit == ("inch" if case.name == "hexapod-sim-inch" else "mm")
    assert case.check.run.linear_unit == unit
    machine = case.machine
    factor = 25.4 if unit == "inch" else 1.0
    values = dict(re.findall(r"^setp genhexkins\.(\S+) (\S+)$", case.hal.read_text(), flags=re.M))
    base = np.array([[float(values[f"base.{n}.{a}"]) for a in "xyz"] for n in range(6)])
    # the calibrated joints rounded to the unit's decimals (1 nm or finer)
    assert np.allclose(base * factor, machine.base, rtol=0,
                       atol=half_unit_mm(factor) + 4 * EPS * np.abs(machine.base).max())


def test_the_comparison_sees_a_micrometre(case):
    """The comparison has teeth: the same LinuxCNC run against the calibrated machine with one
    base joint moved by 1 µm differs by about that much."""
    machine = case.machine
    base = machine.base.copy()
    base[2, 0] += 1e-3
    import dataclasses

    moved = dataclasses.replace(machine, base=base)
    wrong = lc.compare(moved, case.check.run)
    assert 1e-4 < wrong.ik_max <= 1e-3 + 1e-9 + case.check.rounding
    assert case.check.ok and not wrong.ok


# -- pkmcal check linuxcnc -------------------------------------------------------------------

def test_check_command_example_runs_linuxcnc():
    """The example of 'pkmcal check --help' (run here, not by tests/cli/test_examples.py)."""
    require_controller(lc.missing_reason())
    res = ok(run(*"check linuxcnc stewart-prototype".split()))
    assert "world mode: largest |LinuxCNC joint - pkmcal strut length|" in res.stdout
    assert "LinuxCNC moves as pkmcal predicts" in res.stderr


@pytest.mark.parametrize("case", ["hexapod-sim-inch"], indirect=True)
def test_check_command_reads_the_users_files(case):
    """LinuxCNC's own hexapod.ini, updated by 'pkmcal export --update-ini' for the calibrated
    machine, with the HAL file of that export, through 'pkmcal check linuxcnc'."""
    hal, ini = case.folder / "user.hal", case.folder / "hexapod-calibrated.ini"
    ok(run("export", case.calibrated, "--format", "linuxcnc", "-o", hal, "--update-ini", SAMPLE / "hexapod.ini",
           "--ini", ini))
    assert "LINEAR_UNITS = inch" in ini.read_text() and "PYVCP = hexapod.xml" in ini.read_text()
    res = ok(run("check", "linuxcnc", case.calibrated, "--hal", hal, "--ini", ini, "--json"))
    import json

    got = json.loads(res.stdout)
    assert got["ok"] and got["linear_unit"] == "inch" and got["world_mode"]["poses"] >= 20
    assert got["world_mode"]["export_rounding_mm"] <= strut_rounding_mm(25.4)
    assert got["world_mode"]["max_joint_diff_mm"] <= 1e-9 + got["world_mode"]["export_rounding_mm"]
    assert got["joint_mode"]["max_pose_diff_mm"] <= got["joint_mode"]["bound"]


def test_check_without_linuxcnc_is_a_user_error(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))          # no 'linuxcnc' command on it
    assert_user_error(run("check", "linuxcnc", "stewart-prototype"), "LinuxCNC is not installed",
                      "apt-get install linuxcnc-uspace")


def test_host_lock_waits_for_a_live_linuxcnc_and_ignores_a_stale_lock(monkeypatch, tmp_path):
    """LinuxCNC runs once per host: a run waits while another LinuxCNC holds its lock file, and
    a lock file no LinuxCNC process holds (a crashed run) does not block (files of this test's
    own, never LinuxCNC's real /tmp/linuxcnc.lock)."""
    monkeypatch.setattr(lc, "LOCK_FILE", str(tmp_path / "pkmcal.lock"))
    monkeypatch.setattr(lc, "LINUXCNC_LOCK", str(tmp_path / "linuxcnc.lock"))
    (tmp_path / "linuxcnc.lock").write_text("")
    monkeypatch.setattr(lc, "_linuxcnc_processes", lambda: [])
    with lc.host_lock(wait=0.5):
        pass
    monkeypatch.setattr(lc, "_linuxcnc_processes", lambda: [12345])
    with pytest.raises(lc.PkmcalError, match="another LinuxCNC is running"):
        with lc.host_lock(wait=0.5):
            pass
    # and a second pkmcal run waits for the first one's lock
    import fcntl
    import os

    fd = os.open(lc.LOCK_FILE, os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        with pytest.raises(lc.PkmcalError, match="another pkmcal LinuxCNC run"):
            with lc.host_lock(wait=0.5):
                pass
    finally:
        os.close(fd)
