"""The suite's own reproducibility contract (tests/conftest.py): the environment chooses the
Hypothesis profile, and no test overrides what the profile decides (derandomize, database)."""

from __future__ import annotations

import importlib
import tomllib
from pathlib import Path

import pytest
from conftest import hypothesis_profile
from hypothesis import HealthCheck, settings


@pytest.mark.parametrize("environ, profile", [
    ({}, "dev"), ({"CI": "1"}, "ci"), ({"CI": "true"}, "ci"), ({"CI": "false"}, "dev"), ({"CI": "0"}, "dev"),
    ({"CI": ""}, "dev"), ({"HYPOTHESIS_PROFILE": "ci"}, "ci"), ({"CI": "1", "HYPOTHESIS_PROFILE": "dev"}, "dev"),
])
def test_environment_chooses_the_profile(environ, profile):
    assert hypothesis_profile(environ) == profile


def test_profiles():
    ci, dev = settings.get_profile("ci"), settings.get_profile("dev")
    assert ci.derandomize and ci.database is None and ci.deadline is None and ci.print_blob
    assert not dev.derandomize and dev.database is not None and dev.deadline is None
    assert HealthCheck.too_slow in ci.suppress_health_check and HealthCheck.too_slow in dev.suppress_health_check


def test_no_test_overrides_the_profile():
    """Every @given test of the suite runs with the loaded profile's derandomize and example
    database: its @settings(...) sets neither (they would silently defeat the ci profile); no
    deadline, and too_slow is not checked (timing never decides)."""
    loaded = settings.default
    checked = 0
    for path in sorted(Path(__file__).parent.rglob("test_*.py")):
        module = importlib.import_module(path.stem)
        for name, obj in sorted(vars(module).items()):
            own = getattr(obj, "_hypothesis_internal_use_settings", None)
            if name.startswith("test_") and own is not None:
                assert own.derandomize == loaded.derandomize, f"{path.name}::{name} sets derandomize"
                assert own.database == loaded.database, f"{path.name}::{name} sets database"
                assert own.deadline is None, f"{path.name}::{name} has a deadline"
                assert HealthCheck.too_slow in own.suppress_health_check, f"{path.name}::{name} checks too_slow"
                checked += 1
    assert checked >= 60


#: Test modules that check the package as a whole, not one of its subpackages, stay in tests/.
TOP_LEVEL_SUBJECTS = {"api", "allocator", "architecture", "benchmarks", "conventions", "demo", "one_pipeline",
                      "progress", "registries", "suite_settings", "tutorial"}


def test_tests_mirror_the_package():
    """tests/<package>/test_<module>.py: every test folder is a subpackage of src/pkmcal, every
    test module in tests/ itself checks the package as a whole, and basenames are unique (the
    folders are on pytest's ``pythonpath``, so shared fixtures are imported by module name)."""
    tests = Path(__file__).parent
    package = tests.parent / "src" / "pkmcal"
    folders = {p.parent.name for p in tests.rglob("test_*.py") if p.parent != tests}
    assert folders and all((package / name / "__init__.py").exists() for name in folders), folders
    top = {p.stem.removeprefix("test_") for p in tests.glob("test_*.py")}
    assert top <= TOP_LEVEL_SUBJECTS, top - TOP_LEVEL_SUBJECTS
    names = [p.name for p in tests.rglob("*.py") if p.name != "conftest.py"]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
    pyproject = tomllib.loads((tests.parent / "pyproject.toml").read_text())
    on_path = set(pyproject["tool"]["pytest"]["ini_options"]["pythonpath"])
    assert on_path == {"tests"} | {f"tests/{name}" for name in folders}
