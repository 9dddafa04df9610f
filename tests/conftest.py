"""Hypothesis profiles of the suite, loaded before any test module is imported (each test's
``@settings(...)`` copies the loaded profile's values for what it does not set itself, so no
test sets ``derandomize``, ``database`` or a seed: the profile decides them).

* ``dev`` (the default): random examples, failures kept in the example database
  (``.hypothesis/``, git-ignored; ``HYPOTHESIS_STORAGE_DIRECTORY`` moves it) and replayed
  first on the next run.
* ``ci``: reproducible: examples derived from each test's source (``derandomize``), no
  example database, no deadline, and a failure prints the blob that reproduces it.

Both have no deadline and no too_slow health check, so timing never decides a verdict; a
test's own ``suppress_health_check`` replaces the profile's list, so it names too_slow too.

``ci`` is loaded when ``HYPOTHESIS_PROFILE=ci`` or the ``CI`` environment variable is set
(to anything but empty, ``0``, ``false`` or ``no``); ``HYPOTHESIS_PROFILE`` wins over ``CI``.
pytest's ``--hypothesis-profile NAME`` chooses too, after this file.

And one shared fixture: every reproduction run once in quick mode per test session (a few
seconds each; tests/reproduce/test_reproduce.py and tests/reproduce/test_reproduce_issue15.py both read them).
"""

from __future__ import annotations

import os

import pytest
from hypothesis import HealthCheck, settings

# Both start from Hypothesis's own defaults (not from whatever profile Hypothesis loaded itself:
# it loads its built-in "ci" when it sees a CI variable). Timing never decides a verdict: no
# deadline, and the too_slow health check (data generation time on a shared machine) is off.
_DEFAULT = settings.get_profile("default")
settings.register_profile("dev", _DEFAULT, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("ci", _DEFAULT, derandomize=True, database=None, deadline=None, print_blob=True,
                          suppress_health_check=[HealthCheck.too_slow])


def hypothesis_profile(environ=os.environ) -> str:
    """The profile the environment asks for (see the module docstring)."""
    chosen = environ.get("HYPOTHESIS_PROFILE", "").strip()
    if chosen:
        return chosen
    in_ci = environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")
    return "ci" if in_ci else "dev"


settings.load_profile(hypothesis_profile())


@pytest.fixture(scope="session")
def quick_reproductions():
    from pkmcal.reproduce import REPRODUCTIONS, run_reproduction

    return {name: run_reproduction(name, seed=0, quick=True) for name in REPRODUCTIONS}
