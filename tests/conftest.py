"""Shared fixtures: every reproduction run once in quick mode per test session (they take a
few seconds each; tests/test_reproduce.py and tests/test_reproduce_issue15.py both read them)."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def quick_reproductions():
    from pkmcal.reproduce import REPRODUCTIONS, run_reproduction

    return {name: run_reproduction(name, seed=0, quick=True) for name in REPRODUCTIONS}
