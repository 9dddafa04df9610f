"""pkmcal: calibration of parallel kinematic machines.

Calibration is one weighted nonlinear least-squares problem over a machine's kinematic
parameters and, per measured pose, nuisance unknowns (the real pose, joint deflections).
The package is laid out by concern:

* :mod:`pkmcal.mechanisms`     what moves: the mechanism interface, the hexapod, built-ins
* :mod:`pkmcal.sensors`        what is measured: sensor models with analytic derivatives
* :mod:`pkmcal.identification` the engine and its named methods
* :mod:`pkmcal.planning`       which poses to measure
* :mod:`pkmcal.workflow`       a campaign's result: save, verify, export, report
* :mod:`pkmcal.io`, :mod:`pkmcal.cli`   the edges: files and the command line

Units and the pose convention are defined once, in :mod:`pkmcal.conventions`.

The public API (:mod:`pkmcal.api`, docs/api.md) is available here: ``pkmcal.load_machine``,
``pkmcal.plan``, ``pkmcal.simulate``, ``pkmcal.identify``, ``pkmcal.verify``,
``pkmcal.export``, ``pkmcal.report``, ``pkmcal.study``, ... Those names are imported on first use (PEP 562), so that
``import pkmcal`` (and ``pkmcal --help``) stays cheap.
"""

__version__ = "0.1.0"

_API = ("EXPORT_FORMATS", "export", "identifiability", "identify", "load_machine", "load_measurements",
        "load_setup", "perturb", "plan", "report", "save_machine", "save_measurements", "save_setup", "simulate",
        "study", "verify")

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in ("report", "study"):     # subpackages that are also the API functions of their name
        import importlib

        return importlib.import_module(f"pkmcal.{name}")
    if name in _API:
        from pkmcal import api

        return getattr(api, name)
    raise AttributeError(f"module 'pkmcal' has no attribute '{name}'")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
