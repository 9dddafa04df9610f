"""Every example of every ``pkmcal history`` subcommand's ``--help`` runs, in the order the
subcommands are listed, on files made by real commands (plan, simulate, identify twice,
verify --json of a kossel-mini with its Z probe); ``identify --history`` records as it
writes; the options' user errors."""

from __future__ import annotations

import json
import shlex

from click.testing import CliRunner
from helpers import assert_user_error
from test_examples import examples_of, help_text

from pkmcal.cli.history_cmd import history_group
from pkmcal.cli.main import cli
from pkmcal.history.store import open_history

SETUP = ["--setup", "z-probe-klipper"]


def _run(*args: str):
    res = CliRunner().invoke(cli, list(args))
    assert res.exit_code == 0, (args, res.output[-2000:])
    return res


def _campaign(folder):
    _run("plan", "kossel-mini", *SETUP, "--n", "25", "--seed", "1", "-o", str(folder / "p.csv"))
    for k, name in ((2, "m1"), (3, "m2"), (4, "held")):
        _run("simulate", "kossel-mini", "--real", "kossel-mini", *SETUP, "--poses", str(folder / "p.csv"),
             "--seed", str(k), "-o", str(folder / f"{name}.csv"))


def test_every_history_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _campaign(tmp_path)
    _run("identify", "kossel-mini", "m1.csv", *SETUP, "-o", "calibrated.yaml")
    _run("identify", "kossel-mini", "m2.csv", *SETUP, "-o", "recalibrated.yaml")
    res = _run("verify", "recalibrated.yaml", "--held-out", "held.csv", "--setup", "recalibrated.yaml", "--json")
    (tmp_path / "verify.json").write_text(res.stdout)
    ran = 0
    for name in history_group.commands:           # add first: the others read what it recorded
        for example in examples_of(help_text("history", name)):
            res = CliRunner().invoke(cli, shlex.split(example)[1:])
            assert res.exit_code == 0, (example, res.output[-2000:])
            if "--json" in example:
                json.loads(res.stdout)
            ran += 1
    assert ran >= 2 * len(history_group.commands)
    assert (tmp_path / "km-0042.png").read_bytes().startswith(b"\x89PNG")
    with open_history("farm.sqlite", create=False) as hist:
        recs = hist.records(serial="KM-0042")
    assert len(recs) == 2 and recs[0].heldout is None
    assert recs[1].heldout["after"]["n_poses"] == 25           # verify's figures kept with the record


def test_identify_records_into_the_history(tmp_path):
    _campaign(tmp_path)
    db = tmp_path / "h.sqlite"
    out = tmp_path / "cal.yaml"
    res = _run("identify", "kossel-mini", str(tmp_path / "m1.csv"), *SETUP, "-o", str(out), "--history", str(db),
               "--serial", "KM-7", "--held-out", str(tmp_path / "held.csv"))
    assert f"recorded #1 for serial KM-7 in {db}" in res.stdout
    with open_history(db, create=False) as hist:
        rec = hist.get("KM-7")
    assert rec.source == str(out) and rec.heldout["after"]["n_poses"] == 25
    bad = CliRunner().invoke(cli, ["identify", "kossel-mini", str(tmp_path / "m1.csv"), *SETUP, "-o",
                                   str(tmp_path / "x.yaml"), "--history", str(db)])
    assert_user_error(bad, "--serial")
    assert not (tmp_path / "x.yaml").exists()
    bad = CliRunner().invoke(cli, ["identify", "kossel-mini", str(tmp_path / "m1.csv"), *SETUP, "-o", "-",
                                   "--history", str(db), "--serial", "S"])
    assert_user_error(bad, "-o CALIBRATED.yaml")
    corrupt = tmp_path / "corrupt.sqlite"
    corrupt.write_bytes(b"\0garbage" * 100)
    bad = CliRunner().invoke(cli, ["identify", "kossel-mini", str(tmp_path / "m1.csv"), *SETUP, "-o",
                                   str(tmp_path / "x.yaml"), "--history", str(corrupt), "--serial", "S"])
    assert_user_error(bad, "corrupt.sqlite", "not a readable pkmcal history")
    assert not (tmp_path / "x.yaml").exists()                  # refused before anything is written


def test_history_user_errors(tmp_path):
    _campaign(tmp_path)
    _run("identify", "kossel-mini", str(tmp_path / "m1.csv"), *SETUP, "-o", str(tmp_path / "c.yaml"))
    db = str(tmp_path / "h.sqlite")
    run = CliRunner()
    assert_user_error(run.invoke(cli, ["history", "add", str(tmp_path / "m1.csv"), "--serial", "S", "--db", db]),
                      "m1.csv")
    assert_user_error(run.invoke(cli, ["history", "add", "kossel-mini", "--serial", "S", "--db", db]),
                      "no such file")
    bad_json = tmp_path / "v.json"
    bad_json.write_text('{"after": \n oops}')
    assert_user_error(run.invoke(cli, ["history", "add", str(tmp_path / "c.yaml"), "--serial", "S", "--db", db,
                                       "--verification", str(bad_json)]), "v.json, line 2", "pkmcal verify")
    # the first spelling still works, with a deprecation note
    old = run.invoke(cli, ["history", "add", str(tmp_path / "c.yaml"), "--serial", "S", "--db", db, "--heldout",
                           str(bad_json)])
    assert "--heldout is deprecated; use --verification" in old.output and "v.json, line 2" in old.output
    assert_user_error(run.invoke(cli, ["history", "add", str(tmp_path / "c.yaml"), "--serial", "", "--db", db]),
                      "--serial")
    _run("history", "add", str(tmp_path / "c.yaml"), "--serial", "S", "--db", db)
    assert_user_error(run.invoke(cli, ["history", "show", "S~1", "--db", db]), "1 calibration")
    assert_user_error(run.invoke(cli, ["history", "show", "#9", "--db", db]), "no calibration #9")
    assert_user_error(run.invoke(cli, ["history", "show", "T", "--db", db]), "no calibration of serial 'T'")
    assert_user_error(run.invoke(cli, ["history", "fleet", "--model", "nope", "--db", db]), "model 'nope'")
    assert_user_error(run.invoke(cli, ["history", "plot", "S", "-o", str(tmp_path / "f.png"), "--parameter", "zz",
                                       "--db", db]), "zz")
    res = run.invoke(cli, ["history", "compare", "S", "S", "--alpha", "1.5", "--db", db])
    assert res.exit_code == 2 and "--alpha" in res.stderr
