"""``pkmcal fk`` and ``pkmcal info`` never report a pose on another assembly mode, or beyond
the limits, as a good answer (issue 10 items 4 and 7)."""

from __future__ import annotations

import csv
import re

import numpy as np
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.machine_file import load_machine
from pkmcal.io.tables import format_table

WIDE = "symmetric:base_radius=200,platform_radius=150,stroke=300,offset=200,u_joint_tilt=89,s_joint_tilt=89"


def _rows(text: str) -> list[dict[str, str]]:
    """The CSV rows of ``text`` (comment lines skipped), with Python's csv reader."""
    return list(csv.DictReader(ln for ln in text.splitlines() if not ln.startswith("#")))


def run(*args: str):
    return CliRunner().invoke(cli, list(args))


def test_info_does_not_count_other_assembly_modes_as_round_trips():
    """Old behaviour on this machine: "converged 300/300 … max position error 110 mm"."""
    res = run("info", WIDE)
    assert res.exit_code == 0, res.output
    out = res.stdout
    back = re.search(r"returned the pose they came from: (\d+)/300; max position error (\S+) mm", out)
    assert back, out
    other = re.search(r"NOT round trips: (\d+) converged on another assembly mode", out)
    assert other, out
    assert int(back.group(1)) + int(other.group(1)) == 300
    assert int(other.group(1)) > 0
    assert float(back.group(2)) < 1e-6        # the error is over the true round trips only
    assert "lie on another assembly mode than home" in out


def test_fk_flags_readings_beyond_the_stroke(tmp_path):
    """Old behaviour: readings 80 / -30 / 500 on a 0..50 stroke came back converged with no
    limit flag."""
    legs = tmp_path / "legs.csv"
    legs.write_text(format_table({f"lambda{i}": [25.0, 80.0, -30.0, 500.0] for i in range(1, 7)}))
    res = run("fk", "stewart-prototype", str(legs))
    assert res.exit_code == 0, res.output
    rows = _rows(res.stdout)
    assert [r["converged"] for r in rows] == ["1"] * 4
    reach = [r["reachable"] for r in rows]
    assert reach[0] == "ok"
    assert all("stroke" in r for r in reach[1:])
    assert "3 rows violate the machine's limits" in res.stderr and "lines 3, 4, 5" in res.stderr  # line 1: the header


def test_fk_column_same_branch_for_a_guess_on_the_other_mode(tmp_path):
    """Readings of home-mode poses solved from a guess on the other assembly mode: rows that
    converge on a mode other than the guess's get same_branch 0 and are listed on stderr;
    the flag agrees with independent NumPy determinants."""
    m = load_machine(WIDE)
    rng = np.random.default_rng(0)
    half = np.array([250.0, 250.0, 150.0, *np.deg2rad([55.0, 55.0, 80.0])])
    box = m.home_pose + rng.uniform(-1, 1, (20000, 6)) * half
    with np.errstate(all="ignore"):
        box = box[m.check_limits(box).ok]
    sign = np.sign(np.linalg.det(m.twist_jacobian(box)))
    home_sign = np.sign(np.linalg.det(m.twist_jacobian(m.home_pose[None])))[0]
    guess = box[sign != home_sign][0]
    targets = box[sign == home_sign][:200]
    legs = tmp_path / "legs.csv"
    lam = m.ik(targets)
    legs.write_text(format_table({f"lambda{i + 1}": lam[:, i] for i in range(6)}))
    g = ",".join(f"{v:.17g}" for v in np.r_[guess[:3], np.rad2deg(guess[3:])])
    res = run("fk", WIDE, str(legs), "--guess", g)
    assert res.exit_code == 0, res.output
    rows = _rows(res.stdout)
    conv = np.array([r["converged"] == "1" for r in rows])
    same = np.array([r["same_branch"] == "1" for r in rows])
    t = np.array([[float(r[k]) for k in "xyzabc"] for r in rows])
    poses = np.column_stack([t[:, :3], np.deg2rad(t[:, 3:])])
    guess_sign = np.sign(np.linalg.det(m.twist_jacobian(guess[None])))[0]
    got = np.sign(np.linalg.det(m.twist_jacobian(poses[conv])))
    assert np.array_equal(same[conv], got == guess_sign)
    changed = conv & ~same
    if changed.any():
        assert "converged on another assembly mode than the start pose" in res.stderr
    # rows solved on the guess's mode are on the other mode than the targets: not the targets
    assert not np.any(same & conv & (np.linalg.norm(poses[:, :3] - targets[:, :3], axis=1) < 1e-6))
