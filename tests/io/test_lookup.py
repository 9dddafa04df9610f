"""Machines and setups by built-in name or file path (pkmcal.io.lookup)."""

import subprocess
import sys

import pytest

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io import lookup, machine_file, setup_file
from tests.helpers import pkmcal_subprocess_env


def test_built_in_names_load_without_the_file_readers():
    code = ("import sys; from pkmcal.io.lookup import load_machine, load_setup; "
            "m = load_machine('stewart-prototype'); s = load_setup('full-pose-paper1', m); "
            "heavy = [k for k in ('pydantic', 'pkmcal.io.machine_file', 'pkmcal.io.setup_file') if k in sys.modules]; "
            "assert not heavy, heavy; print(m.name, s.sensor.kind)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=pkmcal_subprocess_env())
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["stewart-prototype", "full-pose"]


def test_the_old_import_paths_are_the_same_functions():
    assert machine_file.load_machine is lookup.load_machine
    assert setup_file.load_setup is lookup.load_setup


def test_files_go_to_their_readers_and_round_trip(tmp_path):
    machine = lookup.load_machine("kossel-mini")
    path = tmp_path / "kossel-mini.yaml"          # a file of a built-in's name wins over the built-in
    machine_file.save_machine(machine, path)
    assert lookup.load_machine(path) == machine
    setup_path = tmp_path / "setup.yaml"
    setup_path.write_text("sensor: position\ntarget: {x: 0, y: 0, z: 30}\nnoise: {reading: 0.01, actuator: 0.005}\n")
    hexapod = lookup.load_machine("stewart-prototype")
    assert lookup.load_setup(setup_path, hexapod).sensor.kind == "position"


def test_unknown_names_and_missing_files_are_clear_errors(tmp_path):
    with pytest.raises(InputFileError, match="no such machine file"):
        lookup.load_machine(tmp_path / "missing.yaml")
    with pytest.raises(PkmcalError, match="stewart-prototype"):     # the message lists the built-ins
        lookup.load_machine("no-such-machine")
    with pytest.raises(PkmcalError, match="not a built-in setup .*full-pose-paper1"):
        lookup.load_setup(tmp_path / "missing-setup.yaml")
