"""The tutorials cannot rot: every ``docs/tutorial-*.md`` page's commands run, in order, in a
copy of the folder the page says to copy (its ``cp -r docs/tutorial-files... DIR`` line), and
print what the page shows.

* Every ``$ pkmcal ...`` line of a ``console`` block (with ``\\`` continuations) is run; it
  must exit with 0, or with 2 where the page shows a ``pkmcal: error:`` line.
* Every output line the page shows (not ``...``, nor a line trimmed with ``...``) must be a
  line of what the command printed, numbers compared to three significant digits (digits
  beyond about the tenth are round-off and differ between computers).
* A block after ``<!-- file: NAME -->`` is an excerpt of the file NAME as the commands left
  it, compared the same way.

Page by page, besides:

* tutorial-indicators.md: ``dials_inch.csv`` is ``meas.csv`` of the tutorial in inches (7
  decimals); the shipped setup is the one the page shows.
* tutorial-delta-printer.md: the probe logs are what ``make_probe_logs.py`` writes (its
  fixed seed, byte for byte), and the lines the page quotes from that script (the logs'
  summary and the simulated printer's first layer and 100 mm distances under printer.cfg and
  under the exported saved.cfg) are what it prints.

The pages were written with ``SOURCE_DATE_EPOCH=1798761600`` (2027-01-01, the date in the
calibrated machines' names); so is this run.
"""

from __future__ import annotations

import csv
import importlib.util
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.tables import read_table

DOCS = Path(__file__).resolve().parent.parent / "docs"
PAGE = DOCS / "tutorial-indicators.md"
FILES = DOCS / "tutorial-files"
DELTA_PAGE = DOCS / "tutorial-delta-printer.md"
DELTA_FILES = FILES / "delta"
HEXAPOD_PAGE = DOCS / "tutorial-real-hexapod.md"
HEXAPOD_FILES = FILES / "real-hexapod"
#: Every tutorial page; each is run by a test below.
PAGES = sorted(DOCS.glob("tutorial-*.md"))
NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


def normalise(line: str) -> str:
    """Numbers to 3 significant digits, runs of blanks to one."""
    return " ".join(NUMBER.sub(lambda m: f"{float(m.group()):.3g}", line).split())


def blocks(text: str):
    """(kind, label, lines) of every fenced block: kind is the fence's language, label the
    NAME of a preceding ``<!-- file: NAME -->``."""
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        fence = re.match(r"^```(\w*)\s*$", lines[i])
        if not fence:
            i += 1
            continue
        label = None
        k = i - 1
        while k >= 0 and not lines[k].strip():
            k -= 1
        m = re.match(r"<!-- file: (\S+) -->", lines[k]) if k >= 0 else None
        if m:
            label = m.group(1)
        j = i + 1
        while not lines[j].startswith("```"):
            j += 1
        yield fence.group(1), label, lines[i + 1:j]
        i = j + 1


def commands(lines: list[str]):
    """(argv, shown output lines) of every ``$ pkmcal`` command of a console block."""
    out, k = [], 0
    while k < len(lines):
        line = lines[k]
        if line.startswith("$ "):
            cmd = line[2:]
            while cmd.endswith("\\"):
                k += 1
                cmd = cmd[:-1] + " " + lines[k].strip()
            out.append((shlex.split(cmd), []))
        elif out:
            out[-1][1].append(line)
        k += 1
    return out


def check_shown(shown: list[str], actual: str, what: str) -> None:
    got = {normalise(line) for line in actual.splitlines()}
    for line in shown:
        if "..." in line or not line.strip():
            continue
        assert normalise(line) in got, f"{what}: the page shows\n  {line}\nbut it printed:\n{actual[-3000:]}"


def files_of(page: Path) -> Path:
    """The folder the page tells the reader to copy (``cp -r docs/tutorial-files... DIR``)."""
    m = re.search(r"^cp -r docs/(tutorial-files\S*) \S+", page.read_text(encoding="utf-8"), flags=re.MULTILINE)
    assert m, f"{page.name}: no 'cp -r docs/tutorial-files... DIR' line"
    return DOCS / m.group(1)


def run_page(page: Path, tmp_path, monkeypatch):
    """Run the page's commands in a copy of its folder; check their output and the file
    excerpts. Returns (commands run, excerpts [(name, lines)], the work folder)."""
    work = tmp_path / "work"
    shutil.copytree(files_of(page), work)
    monkeypatch.chdir(work)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1798761600")
    text = page.read_text(encoding="utf-8")
    runner = CliRunner()
    n_run, excerpts = 0, []
    for kind, label, lines in blocks(text):
        if label is not None:
            excerpts.append((label, lines))
        if kind != "console":
            continue
        for argv, shown in commands(lines):
            assert argv[0] == "pkmcal", argv
            res = runner.invoke(cli, argv[1:])
            expected = 2 if any(s.startswith("pkmcal: error:") for s in shown) else 0
            assert res.exit_code == expected, (argv, res.output[-3000:])
            check_shown(shown, res.output, " ".join(argv))
            n_run += 1
    for name, lines in excerpts:
        check_shown(lines, (work / name).read_text(encoding="utf-8"), name)
    return n_run, excerpts, work


def test_every_tutorial_page_is_checked():
    assert set(PAGES) == {PAGE, DELTA_PAGE, HEXAPOD_PAGE}, "a new tutorial page needs its test here"


def test_tutorial_runs_as_written(tmp_path, monkeypatch):
    n_run, excerpts, _ = run_page(PAGE, tmp_path, monkeypatch)
    assert files_of(PAGE) == FILES
    assert n_run >= 10
    assert {name for name, _ in excerpts} >= {"indicators.yaml", "meas.csv", "dials_inch.csv", "kinematics.hal"}
    # the shipped setup is the one the page shows, byte for byte (but for the fence)
    shown_setup = next(lines for name, lines in excerpts if name == "indicators.yaml")
    assert (FILES / "indicators.yaml").read_text(encoding="utf-8").splitlines() == shown_setup


def _probe_logs_script():
    spec = importlib.util.spec_from_file_location("make_probe_logs", DELTA_FILES / "make_probe_logs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_delta_printer_tutorial_runs_as_written(tmp_path, monkeypatch):
    n_run, excerpts, work = run_page(DELTA_PAGE, tmp_path, monkeypatch)
    assert files_of(DELTA_PAGE) == DELTA_FILES
    assert n_run >= 7
    assert {name for name, _ in excerpts} >= {"probe.log", "saved.cfg"}
    # the simulated printer under the config before and after, as the page quotes it
    mk = _probe_logs_script()
    text = DELTA_PAGE.read_text(encoding="utf-8")
    quoted = {normalise(line) for line in text.splitlines()}
    for configs in (("printer.cfg",), ("printer.cfg", "saved.cfg")):
        for line in mk.check(*(str(work / c) for c in configs)):
            assert normalise(line) in quoted, f"the page does not show the check line\n  {line}"


def test_delta_probe_logs_are_what_the_script_writes(tmp_path, capsys):
    """make_probe_logs.py (fixed seed) writes the shipped logs byte for byte, and prints the
    summary the page quotes."""
    mk = _probe_logs_script()
    shutil.copy(DELTA_FILES / "printer.cfg", tmp_path)
    mk.HERE = str(tmp_path)
    mk.main([])
    for name in ("probe.log", "check.log"):
        assert (tmp_path / name).read_bytes() == (DELTA_FILES / name).read_bytes(), name
    quoted = {normalise(line) for line in DELTA_PAGE.read_text(encoding="utf-8").splitlines()}
    printed = capsys.readouterr().out.splitlines()
    assert len(printed) == 2 and all(normalise(line) in quoted for line in printed), printed


def test_real_hexapod_tutorial_runs_as_written(tmp_path, monkeypatch):
    n_run, excerpts, _ = run_page(HEXAPOD_PAGE, tmp_path, monkeypatch)
    assert files_of(HEXAPOD_PAGE) == HEXAPOD_FILES
    assert n_run >= 5
    assert {name for name, _ in excerpts} >= {"campaign.csv", "joints.ini"}


def test_real_hexapod_campaign_is_what_the_script_writes(tmp_path):
    """make_campaign.py (fixed seed) writes the shipped campaign and held-out files byte for
    byte, and the complications the page describes are in them (a reading at its stroke's
    end on row 17, a 5 mm mocap error on row 41)."""
    spec = importlib.util.spec_from_file_location("make_campaign", HEXAPOD_FILES / "make_campaign.py")
    mk = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mk)
    for name in ("hexapod.yaml", "mocap.yaml"):
        shutil.copy(HEXAPOD_FILES / name, tmp_path)
    mk.HERE = str(tmp_path)
    mk.main()
    for name in ("campaign.csv", "heldout.csv"):
        assert (tmp_path / name).read_bytes() == (HEXAPOD_FILES / name).read_bytes(), name
    rows = list(csv.DictReader((HEXAPOD_FILES / "campaign.csv").open()))
    assert len(rows) == 60 and {r["session"] for r in rows} == {"1", "2"}
    assert rows[mk.CLIPPED[0] - 1][f"lambda{mk.CLIPPED[1] + 1}"] == "10.000000"


def test_dials_inch_is_the_tutorials_measurements_in_inches(tmp_path, monkeypatch):
    """The shipped logger file is what the tutorial's simulate writes, converted to inches
    with 7 decimals (so the page's comparison of the two fits holds)."""
    monkeypatch.chdir(tmp_path)
    shutil.copy(FILES / "indicators.yaml", tmp_path)
    runner = CliRunner()
    for argv in (["plan", "stewart-prototype", "--setup", "indicators.yaml", "--n-poses", "45", "--seed", "1",
                  "-o", "poses.csv"],
                 ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators.yaml",
                  "--poses", "poses.csv", "--seed", "2", "-o", "meas.csv"]):
        assert runner.invoke(cli, argv).exit_code == 0, argv
    mm = ("d1", "d2", "d3") + tuple(f"lambda{i}" for i in range(1, 7))
    meas = read_table(tmp_path / "meas.csv", mm)[list(mm)]
    with open(FILES / "dials_inch.csv", newline="") as fh:             # plain csv: read independently
        rows = list(csv.reader(fh))
    assert rows[0] == ["Pose", "DI-A", "DI-B", "DI-C"] + [f"Strut {i}" for i in range(1, 7)]
    log = np.array(rows[1:], dtype=float)
    np.testing.assert_array_equal(log[:, 0], np.arange(1, len(meas) + 1))
    np.testing.assert_allclose(log[:, 1:], meas / 25.4, rtol=0, atol=0.5e-7 + 1e-12)
