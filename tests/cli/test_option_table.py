"""One vocabulary of options (issue 27 item 3): the tables of ``docs/options.md`` against every
command's and subcommand's ``--help``, both ways, and each old spelling: still accepted, hidden
from ``--help``, the same value as the new spelling, and one ``pkmcal: warning: --old is
deprecated; use --new`` line.

A command or option added to pkmcal fails :func:`test_every_option_shown_in_a_help_is_in_the_table`
until its row is added to ``docs/options.md`` (the page says so)."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import click
import pytest
from click.testing import CliRunner
from helpers import command_helps

from pkmcal.cli.main import cli
from pkmcal.cli.options import Option
from pkmcal.errors import PkmcalWarning

DOC = Path(__file__).resolve().parents[2] / "docs" / "options.md"
_TICKED = re.compile(r"`([^`]+)`")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in line.strip().strip("|").split("|")]


def doc_tables(text: str) -> dict[str, list[list[str]]]:
    """The markdown tables of ``text`` by the first cell of their header row: their body rows
    as lists of cells."""
    tables: dict[str, list[list[str]]] = {}
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.startswith("|") and i + 1 < len(lines) and re.fullmatch(r"\|(\s*-+\s*\|)+", lines[i + 1].strip()):
            rows = tables.setdefault(_cells(line)[0], [])
            for body in lines[i + 2:]:
                if not body.startswith("|"):
                    break
                rows.append(_cells(body))
    return tables


def option_table() -> dict[tuple[str, str], set[str]]:
    """``(long name, command)`` → the option's spellings, from every table whose header starts
    with 'option' (one option per row; an option may have several rows, e.g. one with a short
    spelling for one command, never two rows for one command)."""
    table: dict[tuple[str, str], set[str]] = {}
    for row in doc_tables(DOC.read_text(encoding="utf-8"))["option"]:
        spellings = {s for s in _TICKED.findall(row[0]) if s.startswith("-")}
        assert spellings, row
        name = max(spellings, key=len)
        commands = set(_TICKED.findall(row[-1]))
        assert commands, f"{name}: no command listed"
        for command in commands:
            assert (name, command) not in table, f"{name}: two rows for {command}"
            table[name, command] = spellings
    return table


def help_options(text: str) -> dict[str, set[str]]:
    """The options a ``--help`` text shows: long name → its spellings (``--help`` left out)."""
    shown: dict[str, set[str]] = {}
    in_options = False
    for line in text.splitlines():
        if line.strip() == "Options:":
            in_options = True
        elif in_options and re.match(r"  -", line):
            first_column = line.strip().split("  ")[0]
            spellings = set(re.findall(r"(?<![\w-])(--?[A-Za-z0-9][\w-]*)", first_column))
            spellings -= {"-h", "--help"}
            if spellings:
                shown[max(spellings, key=len)] = spellings
    return shown


HELPS = {" ".join(path): (command, text) for path, command, text in command_helps()}
SHOWN = {name: help_options(text) for name, (command, text) in HELPS.items()
         if not isinstance(command, click.Group)}


def test_the_help_parser_reads_a_help_text():
    """help_options finds options with a short spelling, a metavar, a wrapped first column."""
    text = ("Usage: x\n\nOptions:\n  -o, --output FILE   File to write.\n  --calibration-measurements MEAS.csv\n"
            "                      The data (--not-an-option).\n  --json  Print JSON.\n  -h, --help  Show this.\n"
            "\n  Examples:\n    pkmcal x --json\n")
    assert help_options(text) == {"--output": {"-o", "--output"}, "--calibration-measurements":
                                  {"--calibration-measurements"}, "--json": {"--json"}}


def test_every_option_shown_in_a_help_is_in_the_table():
    table = option_table()
    missing = []
    for command, shown in SHOWN.items():
        for name, spellings in shown.items():
            if (name, command) not in table:
                missing.append(f"{name} ({command})")
            else:
                assert spellings == table[name, command], (command, name, spellings, table[name, command])
    assert not missing, f"options without their row (or command) in {DOC.name}: {', '.join(missing)}"


def test_every_command_of_the_table_shows_its_options():
    wrong = [f"{name} ({command})" for name, command in option_table() if name not in SHOWN.get(command, {})]
    assert not wrong, f"rows of {DOC.name} naming a command whose --help does not show the option: {wrong}"


def test_json_and_quiet_on_every_command_that_prints_a_report():
    """Issue 27 item 3: --quiet and --json on every command that prints figures (the commands
    whose main output is a table or a file, and the folder commands, have no --json)."""
    figures = {"info", "ik", "fk", "plan", "observability", "simulate", "identifiability", "identify", "verify",
               "export", "check linuxcnc", "check klipper", "demo", "reproduce", "study", "compensate", "correct",
               "history add", "history list", "history show", "history compare", "history fleet", "history plot"}
    report = figures - {"ik", "fk", "simulate", "study", "correct"}
    assert {c for c in figures if "--quiet" in SHOWN[c]} == figures
    assert {c for c in report if "--json" in SHOWN[c]} == report


# -- old spellings ------------------------------------------------------------------------------

def registered_old_spellings() -> set[tuple[str, str, str]]:
    """``(command, old, new)`` of every :class:`pkmcal.cli.options.Option` old spelling."""
    found = set()
    for name, (command, _) in HELPS.items():
        for param in command.params:
            if isinstance(param, Option):
                found |= {(name, old, max(param.opts, key=len)) for old in param.old_opts}
    return found


def documented_old_spellings() -> set[tuple[str, str, str]]:
    """The same from the old-spellings table of the page (its rows of a plain old option
    spelling: the old cell that spelling alone)."""
    found = set()
    for row in doc_tables(DOC.read_text(encoding="utf-8"))["old spelling"]:
        ticked = _TICKED.findall(row[0])
        if len(ticked) == 1 and row[0] == f"`{ticked[0]}`" and ticked[0].startswith("-"):   # a plain alias
            new = max((s.split()[0] for s in _TICKED.findall(row[1])), key=len)
            found |= {(command, ticked[0].split()[0], new) for command in _TICKED.findall(row[2])}
    return found


#: One case per old spelling: command, the arguments with the old spelling, with the new one.
OLD_SPELLINGS = [
    ("identify", ["m", "meas.csv", "--setup", "s", "--heldout", "h.csv"], ["m", "meas.csv", "--setup", "s", "--held-out", "h.csv"]),
    ("export", ["c.yaml", "--format", "klipper", "--heldout", "h.csv"], ["c.yaml", "--format", "klipper", "--held-out", "h.csv"]),
    ("export", ["c.yaml", "--format", "klipper", "--measurements", "m.csv"],
     ["c.yaml", "--format", "klipper", "--calibration-measurements", "m.csv"]),
    ("verify", ["c.yaml", "--measurements", "h.csv"], ["c.yaml", "--held-out", "h.csv"]),
    ("demo", ["--held-out", "12"], ["--n-held-out", "12"]),
    ("demo", ["--out", "d"], ["--output", "d"]),
    ("plan", ["m", "--setup", "s", "--n", "12"], ["m", "--setup", "s", "--n-poses", "12"]),
    ("compensate", ["c.yaml", "m.csv", "--heldout", "h.csv"], ["c.yaml", "m.csv", "--held-out", "h.csv"]),
    ("compensate", ["c.yaml", "m.csv", "--held-out", "h.csv", "--printer-cfg", "p.cfg"],
     ["c.yaml", "m.csv", "--held-out", "h.csv", "--config", "p.cfg"]),
    ("history add", ["c.yaml", "--serial", "S", "--heldout", "v.json"], ["c.yaml", "--serial", "S", "--verification", "v.json"]),
]


def test_every_old_spelling_is_documented_and_has_a_case():
    registered = registered_old_spellings()
    assert registered == documented_old_spellings()
    assert {(c, o[-2], n[-2]) for c, o, n in OLD_SPELLINGS} == {(c, o, n) for c, o, n in registered}


@pytest.mark.parametrize("command, old, new", OLD_SPELLINGS, ids=[f"{c} {o[-2]}" for c, o, _ in OLD_SPELLINGS])
def test_an_old_spelling_gives_the_new_ones_value_and_warns(command, old, new):
    cmd = HELPS[command][0]

    def parse(args):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            params = cmd.make_context(command, list(args)).params
        return params, [str(w.message) for w in caught if issubclass(w.category, PkmcalWarning)]

    params_old, warned_old = parse(old)
    params_new, warned_new = parse(new)
    assert params_old == params_new
    assert warned_new == [] and warned_old == [f"{old[-2]} is deprecated; use {new[-2]}"]
    assert old[-2] not in help_options(HELPS[command][1])       # hidden from --help
    with pytest.raises(click.UsageError, match="the same option; give it once"):
        cmd.make_context(command, [*new, old[-2], old[-1]])


def test_the_warning_line_on_the_command_line(tmp_path):
    """The note goes through the CLI's warning path: one 'pkmcal: warning:' line on standard
    error, also before a usage error (which ends the command before its own warnings)."""
    res = CliRunner().invoke(cli, ["demo", "--out", str(tmp_path / "d"), "--n-poses", "0"])
    assert res.exit_code == 2
    lines = res.stderr.splitlines()
    assert lines[0] == "pkmcal: warning: --out is deprecated; use --output" and lines[1].startswith("pkmcal: error:")


def test_ik_takes_its_poses_file_as_an_option(tmp_path):
    poses = tmp_path / "p.csv"
    poses.write_text("x,y,z,a,b,c\n0,0,315,0,0,0\n5,-3,320,1,0.5,2\n")
    new = CliRunner().invoke(cli, ["ik", "stewart-prototype", "--poses", str(poses)])
    old = CliRunner().invoke(cli, ["ik", "stewart-prototype", str(poses)])
    assert new.exit_code == old.exit_code == 0
    assert old.stdout == new.stdout and new.stdout.startswith("x,y,z,a,b,c,l1")
    assert "deprecated" not in new.stderr
    assert f"pkmcal: warning: 'pkmcal ik MACHINE {poses}' (the poses file as an argument) is deprecated; use " \
           f"'--poses {poses}'" in old.stderr
    assert CliRunner().invoke(cli, ["ik", "--help"], terminal_width=200).output.splitlines()[0].endswith(
        "ik [OPTIONS] MACHINE")


def test_identify_without_dash_o_writes_to_standard_output(tmp_path, monkeypatch):
    """README: a missing -o means standard output, for identify as for every command."""
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1798761600")   # the calibration record's date
    sim = CliRunner().invoke(cli, ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                                   "full-pose-paper1", "--poses", str(_poses(tmp_path)), "--seed", "1"])
    assert sim.exit_code == 0, sim.output
    meas = tmp_path / "meas.csv"
    meas.write_text(sim.stdout)
    base = ["identify", "stewart-prototype", str(meas), "--setup", "full-pose-paper1", "--name", "cal"]
    bare = CliRunner().invoke(cli, base)
    dash = CliRunner().invoke(cli, [*base, "-o", "-"])
    assert bare.exit_code == dash.exit_code == 0, bare.output
    assert bare.stdout.startswith("# pkmcal machine file")
    assert bare.stdout == dash.stdout.replace("--name cal -o -", "--name cal")   # the record's command line


def _poses(tmp_path) -> Path:
    import numpy as np

    from pkmcal.io.tables import format_table

    rng = np.random.default_rng(3)
    p = rng.uniform(-1, 1, (25, 6)) * [20, 20, 8, 2, 2, 5]
    p[:, 2] += 315.0
    path = tmp_path / "poses.csv"
    path.write_text(format_table({k: p[:, i] for i, k in enumerate("xyzabc")}))
    return path


#: Old option spellings as they would appear in a message or docstring (``--calibration-
#: measurements``, ``--output`` and ``--n-poses`` are not matches; demo's old ``--held-out N``
#: is also the new spelling of held-out files, so it is not searched).
OLD_IN_TEXT = re.compile(r"(?<![\w-])(--heldout\b|--measurements\b|--n(?= [0-9N{]| cycles)|--out\b(?!put)|--printer-cfg\b)")


def test_no_text_names_an_old_spelling():
    """Messages, help texts and docstrings name the new spellings (the declarations of the
    old ones, ``old=(...)``, and cli/options.py's description of the mechanism aside), and so
    do README.md and docs/ (the old-spellings table of docs/options.md aside)."""
    root = Path(__file__).resolve().parents[2]
    found: dict[str, list[str]] = {}
    texts = [p for p in (root / "src" / "pkmcal").rglob("*.py") if p.name != "options.py"]
    texts += [root / "README.md", *(p for p in (root / "docs").glob("*.md") if p.name != "options.md")]
    for path in texts:
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if "old=(" not in line:
                found.setdefault(str(path.relative_to(root)), []).extend(
                    f"{number}: {m.group(1)}" for m in OLD_IN_TEXT.finditer(line))
    counts = {path: len(hits) for path, hits in found.items() if hits}
    assert not counts, {path: found[path] for path in counts}


@pytest.mark.parametrize("args", [["demo", "-o", "-"], ["study", "examples/study-quick.yaml", "-o", "-"]])
def test_dash_o_of_a_folder_command_is_refused(args):
    """'-o -' is standard output everywhere; the commands that write a folder of files say
    that it cannot hold one (it made a folder named '-')."""
    root = Path(__file__).resolve().parents[2]
    res = CliRunner().invoke(cli, [str(root / a) if a.startswith("examples/") else a for a in args])
    assert res.exit_code == 2 and res.stderr.startswith("pkmcal: error: -o -:") and "give a folder name" in res.stderr
