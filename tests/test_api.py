"""The public API (issue 12 item 4): docs/api.md and the docstrings of pkmcal.api run as
doctests; ``import pkmcal`` stays cheap (no NumPy until a function is used); the typed
parameter records line up with the result's names."""

from __future__ import annotations

import doctest
import subprocess
import sys
from pathlib import Path

import pytest
from helpers import pkmcal_subprocess_env

import pkmcal
import pkmcal.api

DOCS = Path(__file__).resolve().parent.parent / "docs"
FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE | doctest.IGNORE_EXCEPTION_DETAIL


def test_docs_api_page_runs():
    result = doctest.testfile(str(DOCS / "api.md"), module_relative=False, optionflags=FLAGS)
    assert result.attempted > 20 and result.failed == 0


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
