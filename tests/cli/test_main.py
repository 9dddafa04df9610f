"""The ``pkmcal`` group: every listed command loads, its summary in the top-level help is its
own first help line, and listing the commands imports none of the heavy libraries."""

from __future__ import annotations

import json
import subprocess
import sys

import click
from click.testing import CliRunner

from pkmcal.cli.main import COMMANDS, cli


def test_every_command_loads_and_its_summary_is_its_own_first_help_line():
    ctx = click.Context(cli)
    for name, (_, _, summary) in COMMANDS.items():
        cmd = cli.get_command(ctx, name)
        assert isinstance(cmd, click.Command) and cmd.name == name, name
        assert cmd.get_short_help_str(limit=10_000) == summary, name


def test_top_level_help_lists_every_command_untruncated():
    out = CliRunner().invoke(cli, ["--help"], terminal_width=80).output
    listing = " ".join(out.split("Commands:")[1].split())       # wrapped lines joined
    for name, (_, _, summary) in COMMANDS.items():
        assert f"{name} {summary}" in listing, name
    assert "..." not in listing


def test_unknown_command_is_a_usage_error():
    result = CliRunner().invoke(cli, ["no-such-command"])
    assert result.exit_code == 2
    assert "No such command" in result.output


def test_help_and_listing_import_no_heavy_library():
    """``pkmcal --help`` must not import NumPy, SciPy, numba, pydantic or matplotlib
    (a fresh interpreter, so nothing else has imported them)."""
    code = ("import sys; from pkmcal.cli.main import main; sys.argv = ['pkmcal', '--help']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "import json; print(json.dumps(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('numpy', 'scipy', 'numba', 'pydantic', 'matplotlib', 'yaml'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []


def test_python_dash_m_pkmcal_is_the_pkmcal_command():
    """``python -m pkmcal`` runs the same group (usage line names ``pkmcal``; a user error
    exits 2 with one line)."""
    ok = subprocess.run([sys.executable, "-m", "pkmcal", "--help"], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.startswith("Usage: pkmcal "), ok.stdout[:200]
    bad = subprocess.run([sys.executable, "-m", "pkmcal", "ik", "no-such-machine", "--poses", "poses.csv"],
                         capture_output=True, text=True)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1, bad.stderr


def test_machines_lists_every_builtin_with_its_kind_and_imports_no_numpy():
    """The listing comes from a plain-text catalogue (no NumPy, pydantic, numba), and the
    kind it shows is the kind of the machine the name builds."""
    from pkmcal.mechanisms.catalogue import BUILTIN_CATALOGUE
    from pkmcal.mechanisms.library import builtin_machine

    code = ("import sys; from pkmcal.cli.main import main; sys.argv = ['pkmcal', 'machines']\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "import json; print(json.dumps(sorted({m.split('.')[0] for m in sys.modules if m.split('.')[0] in "
            "('numpy', 'scipy', 'numba', 'pydantic', 'matplotlib', 'yaml')})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out.strip().splitlines()[-1]) == []
    listing = {line.split()[0]: line.split()[1] for line in out.strip().splitlines()[:-1]}
    for name, (kind, _) in BUILTIN_CATALOGUE.items():
        assert listing[name] == kind == builtin_machine(name).kind, name
    assert listing["symmetric:KEY=VALUE,..."] == builtin_machine("symmetric:base_radius=150").kind
