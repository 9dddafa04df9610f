"""Every ``--help`` has an Examples section, and every example in it runs.

The examples are read from the help texts themselves (``pkmcal --help`` and each command's),
run in one fresh folder (holding a copy of the repository's ``examples/``) in an order where
each file an example reads was written by an earlier one (``-o FILE``, ``--save-real FILE``,
``> FILE``), and must exit with 0 and no deprecation note. ``pkmcal demo`` with its defaults is run by ``tests/test_demo.py``.
"""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from pkmcal.cli.main import COMMANDS, cli
from pkmcal.io.machine_file import load_machine

#: Options whose value is a file or folder the example writes.
OUTPUT_OPTIONS = ("-o", "--output", "--save-real", "--out", "--report", ">")
#: The repository's example input files (``examples/...`` in an example reads them).
EXAMPLE_FILES = Path(__file__).resolve().parents[2] / "examples"
#: Examples run elsewhere (the same command line, by another test).
RUN_ELSEWHERE = {"pkmcal demo": "tests/test_demo.py runs the default demo",
                 "pkmcal check linuxcnc stewart-prototype": "tests/controllers/test_linuxcnc.py runs it where LinuxCNC "
                                                            "is installed (and in CI)"}


def help_text(*path: str) -> str:
    res = CliRunner().invoke(cli, [*path, "--help"], terminal_width=250)
    assert res.exit_code == 0, res.output
    return res.output


def examples_of(text: str) -> list[str]:
    lines = text.splitlines()
    start = next((i for i, line in enumerate(lines) if line.strip() == "Examples:"), None)
    if start is None:
        return []
    out = []
    for line in lines[start + 1:]:
        if not line.strip().startswith("pkmcal "):
            break
        out.append(line.strip())
    return out


def all_examples() -> dict[str, list[str]]:
    found = {"pkmcal": examples_of(help_text())}
    for name in COMMANDS:
        found[name] = examples_of(help_text(name))
    return found


def test_every_help_has_examples_that_use_its_command():
    for name, found in all_examples().items():
        assert found, f"'{name} --help' has no example"
        if name != "pkmcal":
            assert any(e.split()[1] == name for e in found), (name, found)


def _files(tokens: list[str]) -> tuple[set[str], set[str]]:
    """(files read, files written) of one example's arguments."""
    written, read = set(), set()
    for i, tok in enumerate(tokens):
        if i and tokens[i - 1] in OUTPUT_OPTIONS:
            if tok != "-":                      # '-o -': standard output
                written.add(tok)
        elif tok.endswith((".csv", ".yaml", ".yml")) and tok not in OUTPUT_OPTIONS:
            read.add(tok)
        elif i and tokens[i - 1] == "--db":     # pkmcal history: 'add' writes the database, the others read it
            (written if tokens[1:3] == ["history", "add"] else read).add(tok)
    return read - written, written


def test_every_example_runs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    if EXAMPLE_FILES.is_dir():                  # examples may name the repository's example files
        shutil.copytree(EXAMPLE_FILES, tmp_path / "examples")
    pending = []
    for found in all_examples().values():
        pending += [e for e in found if e not in pending and e not in RUN_ELSEWHERE]
    runner = CliRunner()
    while pending:
        ready = [e for e in pending if all((tmp_path / f).exists() for f in _files(shlex.split(e))[0])]
        if not ready:
            missing = {e: sorted(f for f in _files(shlex.split(e))[0] if not (tmp_path / f).exists())
                       for e in pending}
            pytest.fail(f"no example writes the files these examples read: {missing}")
        for example in ready:
            tokens = shlex.split(example)[1:]
            redirect = None
            if ">" in tokens:
                k = tokens.index(">")
                tokens, redirect = tokens[:k], tokens[k + 1]
            res = runner.invoke(cli, tokens)
            assert res.exit_code == 0, (example, res.output[-2000:])
            assert "deprecated" not in res.stderr, (example, res.stderr)
            if redirect is not None:
                (tmp_path / redirect).write_text(res.stdout)
                if redirect.endswith(".yaml"):                 # '-o -' wrote the machine file alone
                    load_machine(tmp_path / redirect)
            for f in _files(shlex.split(example))[1]:
                assert (tmp_path / f).exists(), (example, f)
            pending.remove(example)
