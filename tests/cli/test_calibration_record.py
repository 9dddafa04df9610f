"""The calibration record ``pkmcal identify`` writes into the calibrated machine file: the
machine's own name, the UTC date (``SOURCE_DATE_EPOCH`` fixes it: same inputs, same bytes),
the pkmcal version, the command line and the SHA-256 of every input file — each checked
against an independent computation (hashlib on the files, the date from the epoch)."""

from __future__ import annotations

import hashlib
import json
import re
import shlex

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal import __version__
from pkmcal.cli.main import cli
from pkmcal.io.machine_file import load_machine
from pkmcal.io.setup_file import builtin_setup, setup_to_yaml
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype

EPOCH = "1798761600"            # 2027-01-01T00:00:00Z


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture()
def files(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    rng = np.random.default_rng(3)
    p = rng.uniform(-1, 1, (30, 6)) * [8, 8, 4, 2, 2, 4]
    p[:, 2] += stewart_prototype().home_pose[2]
    (tmp_path / "poses.csv").write_text(format_table({k: p[:, i] for i, k in enumerate("xyzabc")}))
    (tmp_path / "indicators.yaml").write_text(setup_to_yaml(builtin_setup("indicators-prototype")))
    res = run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators.yaml",
              "--poses", "poses.csv", "--seed", 4, "-o", "meas.csv")
    assert res.exit_code == 0, res.output
    return tmp_path


def sha256(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_record_names_dates_and_fingerprints_the_inputs(files, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", EPOCH)
    args = ["identify", "stewart-prototype", "meas.csv", "--setup", "indicators.yaml", "-o", "cal.yaml"]
    res = run(*args)
    assert res.exit_code == 0, res.output
    cal = load_machine(files / "cal.yaml")
    rec = cal.metadata["calibration"]
    assert cal.name == rec["name"] == "stewart-prototype-calibrated-2027-01-01"
    assert rec["calibrated_from"] == "stewart-prototype"
    assert rec["date"] == "2027-01-01T00:00:00Z" and rec["pkmcal_version"] == __version__
    assert shlex.split(rec["command"]) == ["pkmcal", *args]
    inputs = rec["inputs"]
    assert inputs["machine"] == {"builtin": "stewart-prototype"}
    for key, name in (("setup", "indicators.yaml"), ("measurements", "meas.csv")):
        assert inputs[key] == {"file": name, "size_bytes": (files / name).stat().st_size, "sha256": sha256(files / name)}
    # the fit part of the record is still there (export --format json shows it all)
    assert rec["method"] == "fk-residual" and rec["n_poses"] > 0 and len(rec["gauge"]) == 3
    res = run("export", "cal.yaml", "--format", "json")
    assert json.loads(res.stdout)["calibration"] == rec
    assert json.loads(res.stdout)["machine"]["name"] == rec["name"]
    # same inputs, same epoch: the same bytes
    first = (files / "cal.yaml").read_bytes()
    assert run(*args).exit_code == 0 and (files / "cal.yaml").read_bytes() == first


def test_name_option_and_the_clock(files, monkeypatch):
    monkeypatch.delenv("SOURCE_DATE_EPOCH", raising=False)
    res = run("identify", "stewart-prototype", "meas.csv", "--setup", "indicators.yaml", "-o", "cal.yaml",
              "--name", "hexapod-A")
    assert res.exit_code == 0, res.output
    cal = load_machine(files / "cal.yaml")
    rec = cal.metadata["calibration"]
    assert cal.name == rec["name"] == "hexapod-A"
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", rec["date"])
    # the calibrated machine file names itself in the HAL export
    hal = run("export", "cal.yaml", "--format", "linuxcnc").stdout
    assert "machine 'hexapod-A'" in hal


def test_a_bad_epoch_is_one_error_line_and_nothing_written(files, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "yesterday")
    res = run("identify", "stewart-prototype", "meas.csv", "--setup", "indicators.yaml", "-o", "cal.yaml")
    assert res.exit_code == 2 and res.stderr.startswith("pkmcal: error: SOURCE_DATE_EPOCH='yesterday'")
    assert not (files / "cal.yaml").exists()
