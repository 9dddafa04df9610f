"""The suite's own reproducibility contract (tests/conftest.py): the environment chooses the
Hypothesis profile, and no test overrides what the profile decides (derandomize, database)."""

from __future__ import annotations

import importlib
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
    for path in sorted(Path(__file__).parent.glob("test_*.py")):
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
