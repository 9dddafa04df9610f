"""The public API (issue 12 item 4, issue 27 item 1): docs/api.md and the docstrings of
pkmcal.api run as doctests, the page in a folder holding the tutorials' files, and what the
page's real-data campaign writes from Python is what the command line writes, byte for byte
(the calibration record's command line aside); ``import pkmcal`` stays cheap (no NumPy until
a function is used); the typed parameter records line up with the result's names."""

from __future__ import annotations

import doctest
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers import pkmcal_subprocess_env

import pkmcal
import pkmcal.api
from pkmcal.cli.main import cli

DOCS = Path(__file__).resolve().parent.parent / "docs"
FILES = DOCS / "tutorial-files"
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE | doctest.IGNORE_EXCEPTION_DETAIL
#: the date of the tutorials' calibrated machines (2027-01-01), as tests/test_tutorial.py runs them
EPOCH = "1798761600"


def _pkmcal(*argv: str) -> None:
    res = CliRunner().invoke(cli, list(argv))
    assert res.exit_code == 0, (argv, res.output[-2000:])


def _tutorial_folder(folder: Path) -> None:
    """The real-hexapod tutorial's files, and the delta tutorial's imports (its sections 1-2)."""
    shutil.copytree(FILES / "real-hexapod", folder, dirs_exist_ok=True)
    for name in ("printer.cfg", "probe.log", "check.log"):
        shutil.copy(FILES / "delta" / name, folder)
    _pkmcal("import", "klipper", "printer.cfg", "--name", "my-kossel", "-o", "delta.yaml")
    for log in ("probe", "check"):
        _pkmcal("import", "klipper-probe", f"{log}.log", "--machine", "delta.yaml", "-o", f"{log}.csv")


@pytest.fixture(scope="module")
def api_page(tmp_path_factory):
    """docs/api.md run as a doctest in a folder of the tutorials' files: (doctest result, folder)."""
    folder = tmp_path_factory.mktemp("api-page")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(folder)
        mp.setenv("SOURCE_DATE_EPOCH", EPOCH)
        _tutorial_folder(folder)
        result = doctest.testfile(str(DOCS / "api.md"), module_relative=False, optionflags=FLAGS)
    return result, folder


def test_docs_api_page_runs(api_page):
    result, _ = api_page
    assert result.attempted > 40 and result.failed == 0


def test_docs_api_campaign_writes_the_bytes_of_the_command_line(api_page, tmp_path, monkeypatch):
    """The page's campaigns from Python and the same commands (docs/tutorial-real-hexapod.md,
    docs/tutorial-delta-printer.md) write the same files: the calibrated machine files (but for
    the record's command line), the LinuxCNC export, the report page (but for the machine
    file's name, given from Python only once saved), the firmware-limited refit's Klipper
    config."""
    _, page = api_page
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("SOURCE_DATE_EPOCH", EPOCH)
    _tutorial_folder(tmp_path)
    _pkmcal("identify", "hexapod.yaml", "campaign.csv", "--setup", "mocap.yaml", "--length-unit", "m", "--free",
            "b*,a*,L0_*,gain_*", "--fix", "auto", "--reject", "4", "--prior", "[ab]*.z=±1", "--prior", "L0_*=±1",
            "--heldout", "heldout.csv", "-o", "calibrated.yaml", "--report", "report")
    _pkmcal("export", "calibrated.yaml", "--format", "linuxcnc", "-o", "hexapod.hal")
    _pkmcal("identify", "delta.yaml", "probe.csv", "--setup", "z-probe-klipper", "--prior", "arm_*=215±0.1",
            "--free", "angle_*,radius_*,arm_*,endstop_*,lean_*", "--fix", "auto", "-o", "with-leans.yaml")
    _pkmcal("export", "with-leans.yaml", "--format", "klipper", "-o", "leans.cfg")    # the default refit

    def without_command(path: Path) -> list[str]:
        lines = path.read_text(encoding="utf-8").splitlines()
        commands = [k for k, line in enumerate(lines) if line.strip().startswith("command:")]
        assert len(commands) == 1, path
        return lines[:commands[0]] + lines[commands[0] + 1:]

    for name in ("calibrated.yaml", "with-leans.yaml"):
        assert without_command(page / name) == without_command(tmp_path / name), name
        assert "command: null" in (page / name).read_text(encoding="utf-8")
    assert (page / "leans.cfg").read_bytes() == (tmp_path / "leans.cfg").read_bytes()
    hal = pkmcal.export(pkmcal.load_machine(page / "calibrated.yaml"), "linuxcnc")
    assert hal == (tmp_path / "hexapod.hal").read_text(encoding="utf-8")
    for figure in sorted((tmp_path / "report").iterdir()):
        assert (page / "report" / figure.name).read_bytes() == figure.read_bytes(), figure.name


def test_api_docstrings_run():
    result = doctest.testmod(pkmcal.api, optionflags=FLAGS)
    assert result.attempted > 10 and result.failed == 0


def test_every_api_name_is_exported_and_documented():
    assert set(pkmcal.api.__all__) == set(pkmcal._API)
    text = (DOCS / "api.md").read_text()
    for name in pkmcal.api.__all__:
        assert callable(getattr(pkmcal, name)) or name == "EXPORT_FORMATS"
        assert name == "EXPORT_FORMATS" or f"`{name}`" in text, name
    with pytest.raises(AttributeError):
        pkmcal.no_such_function  # noqa: B018


def test_import_pkmcal_does_not_import_numpy():
    code = "import sys, pkmcal; assert 'numpy' not in sys.modules, 'numpy imported'; print(pkmcal.__version__)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=pkmcal_subprocess_env())
    assert out.returncode == 0, out.stderr


def test_export_rejects_unknown_formats():
    from pkmcal.errors import PkmcalError

    with pytest.raises(PkmcalError, match="unknown export format"):
        pkmcal.export(pkmcal.load_machine("stewart-prototype"), "gcode")
