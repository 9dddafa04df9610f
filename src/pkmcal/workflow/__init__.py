"""The workflow layer: a calibration campaign from files or objects to a saved, verified,
exported and reported calibration: the steps ``pkmcal identify``, ``verify``, ``export``
and the Python API (:mod:`pkmcal.api`) share. Algorithms are functions, results are rich
values:

* :func:`~pkmcal.workflow.calibration.calibrate` → :class:`~pkmcal.workflow.calibration.Calibration`
  (``save``, ``verify``, ``export``, ``report``, ``to_dict``);
* :mod:`~pkmcal.workflow.verify`: measured held-out validation of a calibrated machine file
  (``pkmcal verify --held-out``);
* :mod:`~pkmcal.workflow.export`: every controller format, with the firmware-limited refit
  (``pkmcal export``);
* :mod:`~pkmcal.workflow.record`: the calibrated file's record, ``setup:`` and "before";
  :mod:`~pkmcal.workflow.provenance`: dates and input fingerprints;
  :mod:`~pkmcal.workflow.inputs`: a machine as its setup's sensor reads it;
  :mod:`~pkmcal.workflow.text`: a fit in plain text;
* :mod:`~pkmcal.workflow.plan`: which poses to measure (``pkmcal plan``: a
  :class:`~pkmcal.workflow.plan.PosePlan` writes its pose file, a Z probe's macro or G-code,
  and its summary; the ISO 9283 pattern) and how good a set is (``pkmcal observability``);
* :mod:`~pkmcal.workflow.analysis`: what a pose set lets a setup identify (``pkmcal identifiability``);
  :mod:`~pkmcal.workflow.vocabulary`: the options' closed vocabularies (methods, losses, built-in
  machines, ...);
* :mod:`~pkmcal.workflow.machine_info`: a machine's summary, workspace and IK→FK round trip
  (``pkmcal info``); :mod:`~pkmcal.workflow.kinematics`: IK and FK over a table with each row's
  reach verdict (``pkmcal ik``, ``fk``).

The command line (:mod:`pkmcal.cli`) parses options, calls this layer and prints.
"""

__all__ = ["Calibration", "calibrate"]


def __getattr__(name: str):
    """``Calibration`` and ``calibrate`` on first use: a light submodule (the vocabulary's
    machines' catalogue) is imported without NumPy."""
    if name in __all__:
        from pkmcal.workflow import calibration

        return getattr(calibration, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
