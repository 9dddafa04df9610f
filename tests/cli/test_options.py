"""Options spelled the same way in every command: ``--poses`` is a file and ``--n-poses`` a
count (the old ``--poses N`` works with a deprecation note), the poses file of
``observability`` and ``identifiability`` is ``--poses`` (the old positional works with a
note), ``-o`` writes the main output to a file or, with ``-o -``, to standard output, and
``pkmcal machines`` marks the default once."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype

SETUP = ("--setup", "indicators-prototype")


def run(*args, **kw):
    return CliRunner().invoke(cli, [str(a) for a in args], **kw)


def write_poses(path, n=20, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 6)) * [20, 20, 8, 2, 2, 5]
    p[:, 2] += stewart_prototype().home_pose[2]
    path.write_text(format_table({k: p[:, i] for i, k in enumerate("xyzabc")}))
    return path


def test_info_n_poses_and_the_old_spelling(tmp_path):
    new = run("info", "--n-poses", 40)
    old = run("info", "--poses", 40)
    assert new.exit_code == old.exit_code == 0
    assert old.stdout == new.stdout and "IK→FK round trip on 40 random reachable poses" in new.stdout
    assert "deprecated" not in new.stderr
    assert old.stderr == ("pkmcal: warning: '--poses 40' as a number of poses is deprecated; use '--n-poses 40' "
                          "(--poses takes a poses file)\n")
    f = write_poses(tmp_path / "p.csv")
    res = run("info", "--poses", f)
    assert res.exit_code == 0 and f"the 20 poses of {f}" in res.stdout and res.stderr == ""
    res = run("info", "--poses", f, "--n-poses", 5)
    assert res.exit_code == 2 and "not both" in res.stderr


def test_demo_takes_n_poses_and_a_poses_file():
    from pkmcal.cli.options import count_or_poses_file

    assert count_or_poses_file(None, None, 40) == (40, None)
    assert count_or_poses_file(None, 12, 40) == (12, None)
    assert count_or_poses_file("poses.csv", None, 40) == (40, "poses.csv")
    assert count_or_poses_file("25", None, 40) == (25, None)          # the old spelling (and a note)
    res = run("demo", "--help", terminal_width=200)
    assert "--n-poses" in res.output and "--poses POSES.csv" in res.output


def test_poses_file_is_an_option_in_observability_and_identifiability(tmp_path):
    f = write_poses(tmp_path / "p.csv")
    for cmd in ("observability", "identifiability"):
        new = run(cmd, "stewart-prototype", *SETUP, "--poses", f, "--json")
        old = run(cmd, "stewart-prototype", f, *SETUP, "--json")
        assert new.exit_code == old.exit_code == 0, (new.output, old.output)
        assert json.loads(new.stdout) == json.loads(old.stdout)
        assert new.stderr == "" and f"use '--poses {f}'" in old.stderr
        usage = run(cmd, "--help").output.splitlines()[0]
        assert usage.endswith(f" {cmd} [OPTIONS] MACHINE"), usage
        res = run(cmd, "stewart-prototype", *SETUP)
        assert res.exit_code == 2 and "--poses" in res.output
        res = run(cmd, "stewart-prototype", f, *SETUP, "--poses", f)
        assert res.exit_code == 2 and "two poses files" in res.stderr


def test_dash_o_is_standard_output_everywhere(tmp_path):
    f = write_poses(tmp_path / "p.csv")
    ik_file = run("ik", "stewart-prototype", "--poses", f, "-o", tmp_path / "legs.csv")
    ik_dash = run("ik", "stewart-prototype", "--poses", f, "-o", "-")
    assert ik_file.exit_code == ik_dash.exit_code == 0
    assert ik_dash.stdout == (tmp_path / "legs.csv").read_text()
    plan = run("plan", "stewart-prototype", *SETUP, "--n-poses", 15, "--n-candidates", 300, "-o", "-")
    assert plan.exit_code == 0 and plan.stdout.startswith("x,y,z,a,b,c,") and "safety margin" in plan.stderr
    sim = run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", *SETUP, "--poses", f, "-o", "-")
    assert sim.exit_code == 0 and "lambda1" in sim.stdout and "poses measured" in sim.stderr
    meas = tmp_path / "meas.csv"
    meas.write_text(sim.stdout)
    cal = run("identify", "stewart-prototype", meas, *SETUP, "-o", "-")
    assert cal.exit_code == 0 and cal.stdout.startswith("# pkmcal machine file") and "chi2" in cal.stderr
    res = run("identify", "stewart-prototype", meas, *SETUP, "-o", "-", "--json")
    assert res.exit_code == 2 and "standard output" in res.stderr
    for args in (("ik", "stewart-prototype", "--poses", f, "-o", ""), ("ik", "stewart-prototype", "--poses", f, "-o", tmp_path)):
        res = run(*args)
        assert res.exit_code == 2 and res.stderr.startswith("pkmcal: error: -o"), res.stderr


def test_every_output_option_reads_the_same():
    """-o is the output everywhere: a file ('-' = standard output), or a folder (METAVAR/)."""
    from pkmcal.cli.main import COMMANDS

    files, folders = {}, {}
    for name in COMMANDS:
        text = run(name, "--help", terminal_width=300).output
        line = next((line for line in text.splitlines() if line.strip().startswith("-o, --")), None)
        if line is not None:
            metavar = line.split()[2]
            (folders if metavar.endswith("/") else files)[name] = line
    assert set(files) >= {"ik", "fk", "plan", "simulate", "identify", "verify", "export", "reproduce"}
    assert set(folders) >= {"demo"}                      # -o names the output folder of folder commands
    for name, line in files.items():
        assert "'-' = standard output" in line, (name, line)


def test_machines_marks_the_default_once():
    res = run("machines")
    assert res.exit_code == 0
    assert res.stdout.count("default") == 1 and "(default machine) (default)" not in res.stdout
    assert "stewart-prototype " in res.stdout.splitlines()[0] and "(default machine)" in res.stdout.splitlines()[0]


def test_help_texts_show_no_formatting_debris():
    """Issue 27 item 4: '95 %%' (a %-escape click never unescapes) and '[x<=None]' (click's
    range of an unbounded number) were shown in --help."""
    from helpers import command_helps

    for path, _, text in command_helps():
        assert "%%" not in text and "None]" not in text, (path, text)


@pytest.mark.parametrize("args", [
    ["export", "stewart-prototype", "--format", "linuxcnc", "--stroke-margin", "nan"],
    ["export", "kossel-mini", "--format", "marlin", "--steps-per-mm", "inf"],
    ["export", "kossel-mini", "--format", "marlin", "--steps-per-mm", "0"],
    ["import", "marlin", "examples/marlin/m503.txt", "--height", "nan"],
])
def test_number_options_added_for_the_controllers_refuse_non_finite_and_out_of_range_values(args, tmp_path):
    """--stroke-margin, --steps-per-mm and --height were plain floats: NaN and inf were taken
    (a negative margin is the export's own error, tests/cli/test_export_update_ini.py)."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    args = [str(root / a) if a.startswith("examples/") else a for a in args]
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "out")])
    assert res.exit_code == 2 and "Invalid value" in res.stderr, res.output
    assert not (tmp_path / "out").exists()
