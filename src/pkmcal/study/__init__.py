"""Campaign studies: Monte Carlo over simulated calibration campaigns (issue 14).

How many poses, which instrument, what accuracy, how sure: a study file
(:mod:`.schema`) names machines and their parameter-error model, setups, pose plans,
methods, trials, the held-out set and the seed; every trial (:mod:`.trial`) plans,
simulates, identifies and verifies; the trials run in this process, on all local cores or
on a Dask cluster (:mod:`.backends`), into a results folder of part files that ``--resume``
continues (:mod:`.results`); :mod:`.runner` ties it together and writes the tidy table,
the summary with confidence intervals, the figures (:mod:`.plots`) and the page
(:mod:`.page`). ``docs/studies.md`` is the user's guide.
"""

from pkmcal.study.results import COLUMNS, read_trials
from pkmcal.study.runner import StudyRun, run_study
from pkmcal.study.schema import ErrorGroup, MachineSpec, MethodSpec, PlanSpec, SetupSpec, Study, load_study

__all__ = ["COLUMNS", "ErrorGroup", "MachineSpec", "MethodSpec", "PlanSpec", "SetupSpec", "Study", "StudyRun",
           "load_study", "read_trials", "run_study"]

import sys as _sys  # noqa: E402

from pkmcal.api import CallablePackage as _CallablePackage  # noqa: E402

_sys.modules[__name__].__class__ = _CallablePackage   # pkmcal.study(STUDY.yaml, RESULTS) is pkmcal.api.study (issue 27)
