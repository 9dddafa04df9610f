"""The options' closed vocabularies (:mod:`pkmcal.workflow.vocabulary`): each name is the
object of the module that defines it, and the machines' catalogue needs no NumPy."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys

import pkmcal.workflow.vocabulary as vocabulary
from pkmcal.mechanisms.catalogue import BUILTIN_CATALOGUE, SYMMETRIC_KIND, SYMMETRIC_PREFIX


def test_every_name_is_its_homes():
    for name, home in vocabulary._HOMES.items():
        module, there = home if isinstance(home, tuple) else (home, name)
        assert getattr(vocabulary, name) is getattr(importlib.import_module(module), there), name
    assert set(vocabulary.__all__) == set(vocabulary._HOMES) | {"BUILTIN_CATALOGUE", "builtin_machines"}


def test_builtin_machines_lists_the_catalogue_then_the_generator():
    rows = vocabulary.builtin_machines()
    assert [(n, k) for n, k, _ in rows[:-1]] == [(n, k) for n, (k, _) in BUILTIN_CATALOGUE.items()]
    assert rows[-1][:2] == (f"{SYMMETRIC_PREFIX}KEY=VALUE,...", SYMMETRIC_KIND)


def test_the_catalogue_imports_no_numpy():
    code = ("import sys; from pkmcal.workflow.vocabulary import builtin_machines; builtin_machines(); "
            "import json; print(json.dumps(sorted(m for m in ('numpy', 'pkmcal.workflow.calibration') "
            "if m in sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert json.loads(out) == []
