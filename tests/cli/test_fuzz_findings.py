"""One regression test per robustness finding of issue 24 item 4 (a fuzz run of 2,074
malformed inputs), each reproducing the input by hand and asserting the clean result: exit
code 2 with one ``pkmcal: error:`` line naming the file, line or key and what to do, no
traceback, no output or partial output left, the inputs untouched
(:func:`test_fuzz_commands.check_contract`). The old behaviour is in each test's docstring.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import re
import shutil
import signal
import textwrap
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from test_fuzz_commands import check_contract, invoke, make_inputs, snapshot

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io.atomic import check_output_dir, check_output_path, make_folder
from pkmcal.io.delta_firmware import read_klipper, read_marlin
from pkmcal.io.inputs import decode_utf8, open_input, read_input_text
from pkmcal.io.klipper_analyze import read_klipper_analyze
from pkmcal.io.klipper_probe import read_klipper_probe
from pkmcal.io.lookup import load_machine
from pkmcal.io.machine_file import read_machine_file
from pkmcal.io.measurements import load_measurements
from pkmcal.io.setup_file import builtin_setup, read_setup_file
from pkmcal.io.tables import read_table
from pkmcal.study import backends, load_study, run_study
from pkmcal.study.results import ResultFolder, cell, format_row, parse_table, read_trials

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
POSIX_FIFO = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="named pipes are POSIX")


@contextlib.contextmanager
def deadline(seconds: int):
    """Fail instead of hanging: a blocking open() of a named pipe is interrupted by SIGALRM
    (POSIX; elsewhere no deadline, and no named pipes either)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def expire(signum, frame):
        raise AssertionError(f"still running after {seconds} s: the command hangs")
    old = signal.signal(signal.SIGALRM, expire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    make_inputs(d)
    for name in ("klipper/printer.cfg", "klipper/probe-console.log", "marlin/m503.txt", "linuxcnc/hexapod.hal",
                 "linuxcnc/hexapod.ini", "study-quick.yaml"):
        shutil.copy(EXAMPLES / name, d / Path(name).name)
    # Klipper's example-delta.cfg gives each stepper its microsteps; so does this printer
    text = (d / "printer.cfg").read_text()
    (d / "printer.cfg").write_text(text.replace("rotation_distance: 40\nendstop_pin",
                                                "rotation_distance: 40\nmicrosteps: 16\nendstop_pin"))
    return d


def _run(base: Path, tmp_path: Path, args: list[str], fifo: str | None = None, files: dict | None = None):
    """``args`` (``{}``: a fresh copy of the inputs, with ``files`` {name: text} added) run in
    that folder, with ``fifo`` made a named pipe; the contract checked; the result returned."""
    d = tmp_path / "run"
    shutil.copytree(base, d)
    for name, text in (files or {}).items():
        (d / name).write_text(text)
    if fifo is not None:
        os.mkfifo(d / fifo)
    args = [a.replace("{}", str(d)) for a in args]
    before = snapshot(d)
    folders = {p.name for p in d.iterdir() if p.is_dir()}
    with deadline(60):
        res = invoke(args, d)
    check_contract(res, d, before, args)
    if res.exit_code == 2:
        assert {p.name for p in d.iterdir() if p.is_dir()} == folders, f"{args} failed but made a folder"
    return res


def _error(res) -> str:
    assert res.exit_code == 2, res.output
    return res.stderr.strip().removeprefix("pkmcal: error: ")


# -- hangs: a named pipe given to every reader ----------------------------------------------------

FIFO_COMMANDS = {   # (command line, which input is the pipe, what the message calls it)
    "import klipper": (["import", "klipper", "{}/p", "-o", "{}/out.yaml"], "Klipper config"),
    "import marlin": (["import", "marlin", "{}/p", "-o", "{}/out.yaml"], "Marlin settings file"),
    "import klipper-probe": (["import", "klipper-probe", "{}/p", "--machine", "kossel-mini", "-o", "{}/out.csv"],
                             "Klipper file"),
    "import klipper-analyze": (["import", "klipper-analyze", "{}/p", "--machine", "kossel-mini", "-o",
                                "{}/out.csv"], "Klipper file"),
    "import klipper include": (["import", "klipper", "{}/inc.cfg", "-o", "{}/out.yaml"], "Klipper config"),
    "export --config": (["export", "kossel-mini", "--format", "klipper", "--config", "{}/p", "-o", "{}/out.cfg"],
                        "Klipper config"),
    "import linuxcnc hal": (["import", "linuxcnc", "{}/p", "{}/hexapod.ini", "-o", "{}/out.yaml"], "HAL file"),
    "import linuxcnc ini": (["import", "linuxcnc", "{}/hexapod.hal", "{}/p", "-o", "{}/out.yaml"], "INI file"),
    "machine file": (["info", "{}/p.yaml"], "machine file"),
    "setup file": (["identify", "{}/machine.yaml", "{}/meas_ind.csv", "--setup", "{}/p.yaml", "-o",
                    "{}/out.yaml"], "setup file"),
    "measurement file": (["identify", "{}/machine.yaml", "{}/p.csv", "--setup", "{}/ind.yaml", "-o",
                          "{}/out.yaml"], "measurement file"),
    "pose table": (["ik", "{}/machine.yaml", "--poses", "{}/p.csv", "-o", "{}/out.csv"], "table"),
    "candidates": (["plan", "{}/machine.yaml", "--setup", "{}/ind.yaml", "--n-poses", "5", "--candidates", "{}/p.csv",
                    "-o", "{}/out.csv"], "table"),
    "study file": (["study", "{}/p.yaml", "-o", "{}/res"], "study file"),
}


@POSIX_FIFO
@pytest.mark.parametrize("case", sorted(FIFO_COMMANDS))
def test_every_reader_refuses_a_named_pipe(base, tmp_path, case):
    """(Old: every reader, 'import marlin' included, blocked for ever in open() waiting for
    a writer.) Refused before opening it for reading, naming the file and what it is."""
    args, what = FIFO_COMMANDS[case]
    pipe = next((Path(a).name for a in args if a.startswith("{}/p")), "p")
    files = {"inc.cfg": "[include p]\n" + (base / "printer.cfg").read_text()}    # a pipe through [include]
    err = _error(_run(base, tmp_path, args, fifo=pipe, files=files))
    assert f"cannot read the {what}: it is a named pipe (FIFO)" in err and "give its path" in err, err
    assert err.startswith(str(tmp_path / "run" / pipe)), err


def test_devices_and_folders_are_not_input_files(tmp_path):
    """What is not a regular file is refused by the shared reader, whatever it is."""
    for path, kind in ((os.devnull, "a character device"), (str(tmp_path), "a folder")):
        with pytest.raises(InputFileError, match=f"cannot read the machine file: it is {kind}, not a file"):
            open_input(path, "machine file")
    with pytest.raises(InputFileError, match="it does not exist"):
        read_input_text(tmp_path / "none.yaml", "setup file")


# -- tracebacks: a file that is not UTF-8 ---------------------------------------------------------


def _latin1(path: Path, line: int) -> tuple[int, int]:
    """Put 'é' in Latin-1 (0xE9) at the start of comment line ``line`` (1-based) of ``path``;
    returns (byte offset, line) of that byte."""
    lines = path.read_bytes().split(b"\n")
    lines.insert(line - 1, b"# caf\xe9")
    path.write_bytes(b"\n".join(lines))
    return len(b"\n".join(lines[:line - 1])) + 1 + len(b"# caf") - (1 if line == 1 else 0), line


@pytest.mark.parametrize("command", ["klipper", "marlin"])
def test_import_of_a_file_that_is_not_utf8(base, tmp_path, command):
    """(Old: UnicodeDecodeError traceback.) The file, its line and the byte offset, and what to do."""
    name = {"klipper": "printer.cfg", "marlin": "m503.txt"}[command]
    src = base / "nonutf8" / name
    src.parent.mkdir(exist_ok=True)
    shutil.copy(base / name, src)
    offset, line = _latin1(src, 3)
    assert src.read_bytes()[offset] == 0xE9
    err = _error(_run(src.parent, tmp_path, ["import", command, f"{{}}/{name}", "-o", "{}/out.yaml"]))
    assert err == (f"{tmp_path / 'run' / name}, line {line}: not a UTF-8 text file: byte 0xE9 at byte offset {offset} "
                   "is not UTF-8; save it as UTF-8 text"), err


def test_every_reader_names_the_bad_byte(base, tmp_path):
    """Every text reader decodes through one function: the byte, its offset and line."""
    machine, setup = load_machine(str(base / "machine.yaml")), builtin_setup("indicators-prototype")
    readers = {"machine.yaml": read_machine_file, "ind.yaml": read_setup_file, "study-quick.yaml": load_study,
               "poses.csv": lambda p: read_table(p, ("x", "y", "z", "a", "b", "c")),
               "meas_ind.csv": lambda p: load_measurements(p, machine, setup),
               "printer.cfg": read_klipper, "m503.txt": read_marlin}
    for name, reader in readers.items():
        p = tmp_path / name
        shutil.copy(base / name, p)
        offset, line = _latin1(p, 2)
        with pytest.raises(InputFileError) as info:
            reader(p)
        assert info.value.line == line and f"byte 0xE9 at byte offset {offset}" in str(info.value), (name, info.value)
    # a BOM is dropped, and counted in the offset
    with pytest.raises(InputFileError, match="byte 0xFF at byte offset 6 is not UTF-8") as info:
        decode_utf8("f", b"\xef\xbb\xbfa\nb\xff", "table")
    assert info.value.line == 2


def test_klipper_configs_are_read_as_klippers_open_reads_them(base, tmp_path):
    """Klipper reads its config with open(filename, 'r') (klippy/configfile.py
    _read_config_file): a lone CR ends a line, a byte-order mark is kept and its parser then
    refuses the file. Through the shared reader's UTF-8 decoding (old, on main after the
    merge) the CR-only file was one line ('no [printer] kinematics') and the BOM was dropped."""
    lf = base / "printer.cfg"
    cr, bom = tmp_path / "cr.cfg", tmp_path / "bom.cfg"
    cr.write_bytes(lf.read_bytes().replace(b"\n", b"\r"))
    bom.write_bytes(b"\xef\xbb\xbf" + lf.read_bytes())
    assert read_klipper(str(cr)) == read_klipper(str(lf))
    with pytest.raises(InputFileError, match="line 1: .*Klipper's parser refuses it too"):
        read_klipper(str(bom))
    try:    # Klipper's own parser, when the controllers extra is installed
        from klippy import configfile  # noqa: F401
    except ImportError:
        return
    from pkmcal.controllers.klipper import klipper_fileconfig

    klipper_fileconfig(str(cr))
    with pytest.raises(PkmcalError, match="Klipper's parser refuses the file"):
        klipper_fileconfig(str(bom))


# -- tracebacks: Klipper's #*# block ------------------------------------------------------------


def _saved_block(base: Path, tmp_path: Path, extra: str) -> Path:
    """printer.cfg with ``extra`` lines appended to its [delta_calibrate] #*# block, and one
    DELTA_ANALYZE distance (reachable stable positions)."""
    p = tmp_path / "cfg" / "printer.cfg"
    p.parent.mkdir(parents=True, exist_ok=True)
    text = (base / "printer.cfg").read_text()
    text += "#*# distance0 = 60.0\n#*# distance0_pos1 = 23961.000,23961.000,23961.000\n" \
            "#*# distance0_pos2 = 23800.000,23961.000,23961.000\n" + extra
    p.write_text(text)
    return p


@pytest.mark.parametrize("command", ["klipper-probe", "klipper-analyze"])
def test_two_probe_heights_with_the_same_number(base, tmp_path, command):
    """height0 and height00 (old: 'the truth value of an array is ambiguous' traceback, or
    both read): Klipper numbers them height0, height1, ... and refuses an option it does not
    read, so pkmcal refuses it naming the line and the key."""
    cfg = _saved_block(base, tmp_path, "#*# height00 = 0.0\n#*# height00_pos = 23961.000,23961.000,23961.000\n")
    err = _error(_run_klipper(cfg, tmp_path, command))
    # the line of a #*# entry is delta_firmware's (one less than the file's on 2026-12-03: issue 24's parsing work)
    assert re.match(re.escape(f"{tmp_path / 'run' / 'printer.cfg'}, line ") + r"\d+: " + re.escape(
        "[delta_calibrate] height00: Klipper numbers these entries height0, height1, ... without leading zeros"), err), err
    assert "rename or remove it" in err
    gap = _saved_block(base, tmp_path / "gap", "#*# height2 = 0.0\n#*# height2_pos = 23961.000,23961.000,23961.000\n")
    err = _error(_run_klipper(gap, tmp_path / "gap", command))
    assert "[delta_calibrate] height2: there is no height1" in err, err


def _run_klipper(cfg: Path, tmp_path: Path, command: str):
    """``pkmcal import COMMAND cfg --machine`` the machine imported from the same file."""
    folder = cfg.parent
    res = invoke(["import", "klipper", str(cfg), "-o", str(folder / "delta.yaml")], folder)
    assert res.exit_code == 0, res.output
    return _run(folder, tmp_path, ["import", command, "{}/printer.cfg", "--machine", "{}/delta.yaml",
                                   "-o", "{}/out.csv"])


@pytest.mark.parametrize("command", ["klipper-probe", "klipper-analyze"])
def test_a_rotary_delta_for_klippers_probe(base, tmp_path, command):
    """(Old: AttributeError 'RotaryDelta' object has no attribute 'reading_reference'.)"""
    err = _error(_run(base, tmp_path, ["import", command, "{}/printer.cfg", "--machine", "delta-picker",
                                       "-o", "{}/out.csv"]))
    assert err.startswith("--machine delta-picker: ") and "read with a linear delta printer" in err, err
    assert "machine 'delta-picker' is a rotary-delta" in err and "kossel-mini" in err, err
    reader = read_klipper_probe if command == "klipper-probe" else read_klipper_analyze
    with pytest.raises(PkmcalError, match="is a rotary-delta"):
        reader(base / "printer.cfg", load_machine("delta-picker"))


# -- studies -------------------------------------------------------------------------------------

STUDY = """\
name: findings
seed: 0
trials: 2
machines:
  - nominal: stewart-prototype
    real: stewart-prototype-real
    ignore_limits: [leg_collision]
setups:
  - {setup: indicators-prototype, label: indicators}
plans:
  - {algorithm: random, poses: [15]}
methods: [auto]
heldout: {poses: 5}
"""


def _study(tmp_path: Path, text: str = STUDY, name: str = "study.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_text_cells_round_trip_through_csv_and_pandas(tmp_path):
    """The writer quotes a line break (old: csv.writer with lineterminator='' left '\\n'
    unquoted, and the readers split records at line ends: IndexError after all trials and
    again under --resume); what it writes, csv and pandas read back exactly."""
    names = ("config", "machine", "trial", "failed", "message", "chi2")
    texts = ["two\nlines", "cr\rlf\r\n", 'a "quoted", comma', " padded ", "sep\u2028char", "plain", ""]
    rows = [format_row({"config": 0, "machine": t, "trial": k, "failed": True, "message": texts[-1 - k],
                        "chi2": 0.1 * k}, names) for k, t in enumerate(texts)]
    folder = ResultFolder(tmp_path / "r", "f", names)
    folder.open(False, "s", len(texts))
    folder.write_part(0, 0, len(texts) - 1, rows)
    back = folder.read_parts(len(texts))
    assert back == rows
    cols = parse_table(names, back)
    assert list(cols["machine"]) == texts and list(cols["message"]) == texts[::-1]
    (tmp_path / "trials.csv").write_text(",".join(names) + "\n" + "".join(r + "\n" for r in back), newline="")
    assert list(read_trials(tmp_path / "trials.csv")["machine"]) == texts
    df = pd.read_csv(tmp_path / "trials.csv", keep_default_na=False)
    assert list(df["machine"]) == texts and list(df["message"]) == texts[::-1]
    with open(tmp_path / "trials.csv", newline="", encoding="utf-8") as fh:
        assert [r[1] for r in list(csv.reader(fh))[1:]] == texts
    assert cell("a\nb", "str") == '"a\nb"' and cell("plain", "str") == "plain"


def test_a_setup_label_with_a_newline_runs_and_resumes(tmp_path, monkeypatch):
    """A study whose setup label holds a newline: trials.csv read back exactly, and a
    resumed run (one part file lost) gives the same bytes."""
    study = load_study(_study(tmp_path, STUDY.replace("label: indicators", 'label: "indi\\ncators"')))
    assert study.setups[0].label == "indi\ncators"
    monkeypatch.setattr(backends, "TARGET_SECONDS", 1e-9)        # one trial per part
    out = tmp_path / "r"
    run_study(study, out, workers=1, figures=False)
    ref = (out / "trials.csv").read_bytes()
    assert list(pd.read_csv(out / "trials.csv")["setup"]) == ["indi\ncators"] * 2
    assert list(read_trials(out / "trials.csv")["setup"]) == ["indi\ncators"] * 2
    os.unlink(sorted((out / "parts").iterdir())[-1])
    res = run_study(study, out, workers=1, resume=True, figures=False)
    assert res.trials_run == 1 and (out / "trials.csv").read_bytes() == ref


def test_a_trial_message_with_newlines(tmp_path):
    """A real machine 100 m off (errors of 1e5 mm) reaches none of the poses: every trial
    fails with the simulation's message of several lines (old: IndexError after all trials,
    and again under --resume). The study ends (exit 0, the failures noted), and pandas and
    a resumed run read the message back exactly."""
    text = STUDY.replace("    real: stewart-prototype-real\n",
                         '    errors:\n      - {parameters: "b*", distribution: normal, size: 1.0e5}\n')
    p, out = _study(tmp_path, text), tmp_path / "r"
    args = ["study", str(p), "-o", str(out), "--workers", "1", "--no-figures"]
    res = invoke(args, tmp_path)
    assert res.exit_code == 0 and "100.0% of the trials of configuration 0 failed" in res.stdout, res.output
    messages = list(pd.read_csv(out / "trials.csv")["message"])
    assert len(messages) == 2 and all(m.startswith("the real machine reaches none of the 15 planned poses") and
                                      "\n  dropped (fk-not-converged" in m for m in messages), messages
    assert list(read_trials(out / "trials.csv")["message"]) == messages
    ref = (out / "trials.csv").read_bytes()
    os.unlink(sorted((out / "parts").iterdir())[-1])
    assert invoke(args + ["--resume"], tmp_path).exit_code == 0
    assert (out / "trials.csv").read_bytes() == ref


def test_a_study_label_with_a_newline_keeps_stdout_one_line_per_configuration(tmp_path):
    res = invoke(["study", str(_study(tmp_path, STUDY.replace("label: indicators", 'label: "a\\nb"'))), "-o",
                  str(tmp_path / "r"), "--workers", "1", "--no-figures"], tmp_path)
    assert res.exit_code == 0, res.output
    assert "stewart-prototype | a\\nb | random 15 | auto" in res.stdout, res.stdout


def _study_error(tmp_path: Path, text: str) -> str:
    p = _study(tmp_path, text)
    res = invoke(["study", str(p), "-o", str(tmp_path / "res"), "--workers", "1", "--no-figures"], tmp_path)
    assert not (tmp_path / "res").exists(), "a refused study left a results folder"
    return _error(res)


def test_an_error_size_of_1e308(tmp_path):
    """(Old: OverflowError 'high - low range exceeds valid bounds' in the first trial, after
    the results folder was made.) Refused on load, naming the key and its line."""
    text = STUDY.replace("    real: stewart-prototype-real\n",
                         '    errors:\n      - {parameters: "b*", distribution: uniform, size: 1e308}\n')
    err = _study_error(tmp_path, text)
    assert err.startswith(f"{tmp_path / 'study.yaml'}, line 7: key 'machines[0].errors[0].size': 1e+308 is beyond "
                          "±1e+06"), err


@pytest.mark.parametrize("edit, key, said", [
    ("trials: 2|trials: true", "trials", "expected a whole number, got true; true/false is not a number"),
    ('trials: 2|trials: "10"', "trials", "expected a whole number, got '10'; it is quoted text: remove the quotes"),
    ("trials: 2|trials: 2.5", "trials", "expected a whole number, got 2.5"),
    ("seed: 0|seed: false", "seed", "expected a whole number, got false"),
    ("poses: [15]|poses: [15, true]", "plans[0].poses[1]", "expected a whole number, got true"),
    ("poses: 5}|poses: '5'}", "heldout.poses", "expected a whole number, got '5'; it is quoted text"),
    ("label: indicators}|label: indicators, actuator_noise_scale: '2'}", "setups[0].actuator_noise_scale",
     "expected a number, got '2'"),
    ("label: indicators}|label: indicators, reading_noise_scale: [1, true]}", "setups[0].reading_noise_scale[1]",
     "expected a number, got true"),
    ("label: indicators}|label: indicators, on_bed: 1}", "setups[0].on_bed", "expected true or false, got 1"),
    ("methods: [auto]|methods: [{method: auto, weighted: 'no'}]", "methods[0].weighted",
     "expected true or false, got 'no'"),
])
def test_quoted_or_boolean_numbers_in_a_study(tmp_path, edit, key, said):
    """(Old: 'trials: true' ran one trial, 'trials: "10"' ten: pydantic's lax mode.)"""
    old, new = edit.split("|")
    assert old in STUDY
    err = _study_error(tmp_path, STUDY.replace(old, new))
    assert f": key '{key}': {said}" in err and ", line " in err, err


@pytest.mark.parametrize("method, key, hint", [
    ("{method: auto, fix: [b1.xx]}", "fix[0]", "did you mean 'b1.x'"),
    ("{method: auto, free: ['b*', 'L0_7']}", "free[1]", "did you mean 'L0_6'"),
    ("{method: fk-residual, free: ['q*']}", "free[0]", "the parameters are b1.x, b1.y"),
])
def test_a_misspelt_parameter_in_a_method(tmp_path, method, key, hint):
    """(Old: every trial failed with '--fix: no parameter matches' in trials.csv, and the
    study exited 0.) Refused on load: the file, the line, the method, the name, close names."""
    err = _study_error(tmp_path, STUDY.replace("methods: [auto]", f"methods: [{method}]"))
    pat = key.split("[")[0]
    assert f"study.yaml, line 12: key 'methods[0].{key}': " in err and "names no parameter of machine " \
        "'stewart-prototype' with setup 'indicators', so every trial of method" in err and hint in err, (pat, err)


def test_a_study_that_cannot_start_leaves_no_folder(tmp_path, monkeypatch):
    """An unreachable Dask scheduler (old: the pilot trials ran first, the connection failed
    20 s later and left RESULTS/ with a manifest and a part: the same command was then
    refused as 'an unfinished study'). The cluster is reached before the folder is made, so
    the same command can simply be run again."""
    def unreachable(address, workers):
        raise PkmcalError(f"cannot reach the Dask scheduler at '{address}': Timed out trying to connect; start one "
                          "with 'dask scheduler' or use --dask local")
    monkeypatch.setattr(backends, "dask_client", unreachable)
    p = _study(tmp_path)
    for _ in range(2):
        res = invoke(["study", str(p), "-o", str(tmp_path / "res"), "--dask", "tcp://127.0.0.1:1"], tmp_path)
        err = _error(res)
        assert err.startswith("cannot reach the Dask scheduler at 'tcp://127.0.0.1:1'"), err
        assert not (tmp_path / "res").exists()


def test_a_failed_study_keeps_only_what_resume_needs(tmp_path, monkeypatch):
    """A failure before any trial finished removes what the run created (an existing empty
    folder is kept); after some finished, they stay, and the message says --resume."""
    study = load_study(_study(tmp_path))
    real = backends.run_batch
    calls = []

    def failing(after):
        def run(*args):
            calls.append(args)
            if len(calls) > after:
                raise PkmcalError("the cluster went away")
            return real(*args)
        return run

    monkeypatch.setattr(backends, "TARGET_SECONDS", 1e-9)
    monkeypatch.setattr("pkmcal.study.runner.run_batch", failing(0))
    with pytest.raises(PkmcalError, match="^the cluster went away$"):
        run_study(study, tmp_path / "new" / "r", workers=1, figures=False)
    assert not (tmp_path / "new" / "r").exists() and (tmp_path / "new").exists() is False
    (tmp_path / "empty").mkdir()
    calls.clear()
    with pytest.raises(PkmcalError, match="^the cluster went away$"):
        run_study(study, tmp_path / "empty", workers=1, figures=False)
    assert (tmp_path / "empty").is_dir() and not list((tmp_path / "empty").iterdir())
    calls.clear()
    monkeypatch.setattr("pkmcal.study.runner.run_batch", real)
    monkeypatch.setattr(backends, "run_batch", failing(0))     # the pilot (here) finishes, the rest fails
    with pytest.raises(PkmcalError, match="the cluster went away; the finished trials are in .*--resume"):
        run_study(study, tmp_path / "r", workers=1, figures=False)
    assert json.loads((tmp_path / "r" / "manifest.json").read_text())["complete"] is False
    monkeypatch.setattr(backends, "run_batch", real)
    assert run_study(study, tmp_path / "r", workers=1, resume=True, figures=False).trials_run == 1


# -- output into a folder nothing can be written in -------------------------------------------


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
@pytest.mark.parametrize("args", [
    ["identify", "{}/machine.yaml", "{}/meas_ind.csv", "--setup", "{}/ind.yaml", "-o", "{}/out.yaml", "--report",
     "/proc/pkmcal-report"],
    ["demo", "-o", "/proc/pkmcal-demo"],
    ["study", "{}/study-quick.yaml", "-o", "/proc/pkmcal-study"],
    ["identify", "{}/machine.yaml", "{}/meas_ind.csv", "--setup", "{}/ind.yaml", "-o", "/proc/out.yaml"],
])
def test_output_into_a_folder_nothing_can_be_written_in(base, tmp_path, args):
    """/proc passes the permission check for a superuser, and nothing can be created in it
    (old, as root: a FileNotFoundError traceback after the fit, with out.yaml already
    written). The location is tried before any work: exit 2 and no file."""
    err = _error(_run(base, tmp_path, args))
    assert err.startswith("cannot write ") and "'/proc'" in err, err
    assert not (tmp_path / "run" / "out.yaml").exists()


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_locations_are_tried_not_only_checked(tmp_path):
    for check in (lambda: check_output_dir("/proc/x/y", "--report"), lambda: check_output_path("/proc/x.csv"),
                  lambda: make_folder("/proc/x", "the report folder")):
        with pytest.raises(PkmcalError, match="'/proc"):
            check()
    check_output_dir(tmp_path / "new" / "folder")
    check_output_path(tmp_path / "out.csv")
    assert list(tmp_path.iterdir()) == []       # the trial files are gone


# -- an output that is a device or a named pipe -----------------------------------------------------


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes on this system")
def test_an_output_that_is_a_named_pipe_is_written_into_not_replaced(tmp_path):
    """(Old: the atomic write's os.replace put a regular file where the pipe was; as root,
    '-o /dev/null' turned /dev/null into a file, 2026-12-03.) A character device or a named
    pipe is written in place: here a reader gets the whole table and the pipe stays a pipe
    (a FIFO rather than /dev/null itself, which a regression would destroy)."""
    import stat
    import threading

    from pkmcal.io.atomic import atomic_write_text

    pipe = tmp_path / "out.csv"
    os.mkfifo(pipe)
    got = []
    reader = threading.Thread(target=lambda: got.append(pipe.read_text()), daemon=True)
    reader.start()
    check_output_path(pipe)
    atomic_write_text(pipe, "x,y\n1,2\n")
    reader.join(timeout=30)
    assert got == ["x,y\n1,2\n"] and stat.S_ISFIFO(os.stat(pipe).st_mode)
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]          # no temporary file left
