"""The plan from Python is the command line's (pkmcal.workflow.plan, issue 27): the pose file,
a Z probe's Klipper macro and the summary that ``pkmcal.plan`` gives are the bytes and the
JSON of ``pkmcal plan``; ``observability_of`` is ``pkmcal observability --json``; the ISO
9283 pattern's file is ``plan --pattern iso9283``'s."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

import pkmcal
from pkmcal.cli.main import cli
from pkmcal.planning.plan import Plan
from pkmcal.workflow.plan import iso9283_plan, observability_of, plan_inputs


def test_a_plan_from_python_writes_and_says_what_the_cli_does(tmp_path):
    m = pkmcal.load_machine("kossel-mini")
    s = pkmcal.load_setup("z-probe-klipper", m)
    p = pkmcal.plan(m, s, 20, seed=3, n_candidates=400)
    assert isinstance(p, Plan) and p.on_bed and p.poses.shape == (20, 3)
    command = "pkmcal plan kossel-mini --setup z-probe-klipper --n-poses 20 --algorithm default --seed 3"
    args = ["plan", "kossel-mini", "--setup", "z-probe-klipper", "--n-poses", "20", "--seed", "3",
            "--n-candidates", "400", "--target-accuracy", "0.01"]
    res = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "p.csv"), "--json"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "p.csv").read_text() == p.csv(command)
    assert json.loads(res.stdout) == {**p.summary(0.01), "output": str(tmp_path / "p.csv")}
    res = CliRunner().invoke(cli, [*args[:-2], "--format", "klipper", "-o", str(tmp_path / "p.cfg")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "p.cfg").read_text() == p.printer_file("klipper", command, "kossel-mini", "z-probe-klipper")


def test_observability_and_the_iso9283_pattern_are_the_cli_s(tmp_path):
    res = CliRunner().invoke(cli, ["plan", "stewart-prototype", "--setup", "laser-tracker", "--pattern", "iso9283",
                                   "--cycles", "3", "-o", str(tmp_path / "iso.csv")])
    assert res.exit_code == 0, res.output
    nominal, setup, margin = plan_inputs("stewart-prototype", "laser-tracker")
    pat = iso9283_plan(nominal, setup, 3, margin=margin)
    command = "pkmcal plan stewart-prototype --setup laser-tracker --pattern iso9283 --cycles 3"
    assert (tmp_path / "iso.csv").read_text() == pat.csv(command)
    assert pat.n_poses == 15 and pat.summary()["cycles"] == 3
    found = observability_of("stewart-prototype", "laser-tracker", str(tmp_path / "iso.csv"))
    res = CliRunner().invoke(cli, ["observability", "stewart-prototype", "--setup", "laser-tracker", "--poses",
                                   str(tmp_path / "iso.csv"), "--json"])
    assert res.exit_code == 0, res.output
    shown = json.loads(res.stdout)
    assert shown["n_poses"] == len(found.poses) == 15 and shown["warnings"] == found.notes
    assert all(np.isclose(shown[k], v) for k, v in found.indices.items())
