"""The workflow layer (pkmcal.workflow, issue 27): a Calibration made from files or from
objects is the same fit; it refuses, accepts or warns about a bad fit as asked, says so in its
record, and never writes over an input; its measured held-out validation is that of the
calibrated file; a delta's export from Python refits for the firmware as ``pkmcal export``
does. Byte-for-byte agreement with the command line on the tutorials' data is
tests/test_api.py's (docs/api.md)."""

from __future__ import annotations

import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import pkmcal
from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError, PkmcalWarning
from pkmcal.workflow import calibrate

FILES = Path(__file__).resolve().parents[2] / "docs" / "tutorial-files"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A simulated indicator campaign and held-out data of the built-in prototype (files), and
    the real-hexapod tutorial's files."""
    work = tmp_path_factory.mktemp("workflow")
    shutil.copytree(FILES / "real-hexapod", work, dirs_exist_ok=True)
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(work)
        for argv in (["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n", "45", "--seed", "1",
                      "-o", "poses.csv"],
                     ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                      "indicators-prototype", "--poses", "poses.csv", "--seed", "2", "-o", "meas.csv"],
                     ["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n", "20", "--algorithm",
                      "random", "--seed", "9", "-o", "held.csv"],
                     ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                      "indicators-prototype", "--poses", "held.csv", "--seed", "3", "-o", "heldmeas.csv"]):
            res = CliRunner().invoke(cli, argv)
            assert res.exit_code == 0, res.output
    return work


def test_objects_and_files_give_the_same_fit(folder, monkeypatch):
    monkeypatch.chdir(folder)
    from_files = calibrate("stewart-prototype", "indicators-prototype", "meas.csv")
    machine = pkmcal.load_machine("stewart-prototype")
    setup = pkmcal.load_setup("indicators-prototype", machine)
    from_objects = calibrate(machine, setup, pkmcal.load_measurements("meas.csv", machine, setup))
    assert np.array_equal(from_files.estimate, from_objects.estimate)
    record = from_objects.machine.metadata["calibration"]
    assert record["inputs"]["machine"] == {"python": "(python Hexapod 'stewart-prototype')"}
    assert record["command"] is None and record["measurements"] == "(python Measurements)"
    assert from_files.machine.metadata["calibration"]["inputs"]["measurements"]["file"] == "meas.csv"


def test_validation_and_export_of_the_object_are_those_of_its_file(folder, tmp_path, monkeypatch):
    monkeypatch.chdir(folder)
    cal = pkmcal.identify("stewart-prototype", "indicators-prototype", "meas.csv")
    cal.save(tmp_path / "cal.yaml")
    # its exports are those of the file it saved ('pkmcal export CAL --format json' names the file)
    assert pkmcal.export(cal, "json") == pkmcal.export(tmp_path / "cal.yaml", "json")
    mine = cal.verify("heldmeas.csv").to_dict()
    theirs = pkmcal.verify(tmp_path / "cal.yaml", heldout="heldmeas.csv").to_dict()
    for when in ("before", "after", "after_reregistered"):
        assert mine[when]["reading_rms_mm"] == theirs[when]["reading_rms_mm"], when
    # measured on poses the fit never saw, the calibration reads far closer than the nominal machine
    assert mine["after"]["reading_rms_mm"] < 0.2 * mine["before"]["reading_rms_mm"]


def test_save_never_writes_over_an_input(folder, monkeypatch):
    monkeypatch.chdir(folder)
    cal = calibrate("stewart-prototype", "indicators-prototype", "meas.csv")
    before = Path("meas.csv").read_bytes()
    with pytest.raises(PkmcalError, match="meas.csv"):
        cal.save("meas.csv")
    assert Path("meas.csv").read_bytes() == before


def test_a_bad_fit_is_refused_warned_or_accepted_as_asked(folder, monkeypatch):
    """The tutorial's campaign read in mm instead of metres (no --length-unit m): chi2 far
    beyond the noise, which 'pkmcal identify' refuses."""
    monkeypatch.chdir(folder)
    with pytest.raises(PkmcalError, match="the fit is refused"):
        calibrate("hexapod.yaml", "mocap.yaml", "campaign.csv")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cal = pkmcal.identify("hexapod.yaml", "mocap.yaml", "campaign.csv")
    assert any(issubclass(w.category, PkmcalWarning) and "would refuse this fit" in str(w.message) for w in caught)
    assert not cal.verdict.acceptable
    assert cal.machine.metadata["calibration"]["accepted_bad_fit"]["problems"] == list(cal.verdict.problems)
    accepted = calibrate("hexapod.yaml", "mocap.yaml", "campaign.csv", bad_fit="accept")
    assert any("written with --accept-bad-fit" in w for w in accepted.warnings)
    with pytest.raises(PkmcalError, match="bad_fit"):
        calibrate("hexapod.yaml", "mocap.yaml", "campaign.csv", bad_fit="maybe")
