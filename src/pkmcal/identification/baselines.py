"""The identification baselines of paper 3 §1 for redundantly actuated machines, through the engine.

Paper 3 (Jeon et al.) compares its projection method with two ways of calibrating a
redundant machine as if it were not redundant; each is the engine's ``projection`` fit on
changed inputs (:func:`baseline_inputs`), as ``pkmcal identify --method …``:

* ``ignore-redundancy``: the encoder readings replaced by the commands c = IK(x_c, ρ_nom) of
  the commanded poses (the actuators assumed at their commands, following errors ignored);
* ``actuator-subset``: only n of the l actuators are used
  (:class:`~pkmcal.identification.projection.ActuatorSubset`), a non-redundant fit.

:func:`baseline_result` turns the engine's result back into one of the nominal machine's kind;
:func:`identify_by_method` is the one call of the engine by a method name that may be a baseline
(``pkmcal identify`` through :func:`pkmcal.workflow.calibrate`, the studies' trials, paper 3's
reproduction).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.identification.projection import ActuatorSubset
from pkmcal.identification.simulation import settles_at_equilibrium
from pkmcal.identification.uncertainty import embed
from pkmcal.mechanisms.base import Mechanism
from pkmcal.sensors.base import MeasurementSetup

#: Identification baselines for redundant machines (``pkmcal identify --method``).
BASELINES = ("ignore-redundancy", "actuator-subset")


def baseline_inputs(method: str, nominal: Mechanism, setup: MeasurementSetup, meas, keep=None):
    """``(machine, setup, measurements)`` that turn the engine's ``projection`` fit into the
    baseline ``method`` (module docstring); ``keep`` the actuators of ``actuator-subset``
    (0-based; default the first n). ``ignore-redundancy`` needs the cmd_ columns."""
    if method not in BASELINES:
        raise PkmcalError(f"unknown baseline '{method}'; use one of {', '.join(BASELINES)}")
    if not settles_at_equilibrium(nominal):
        raise PkmcalError(f"--method {method} is a baseline for redundantly actuated machines; machine "
                          f"'{nominal.name}' has {nominal.n_actuators} actuators for {nominal.n_dof} pose coordinates")
    if method == "ignore-redundancy":
        if meas.commanded is None:
            raise PkmcalError("--method ignore-redundancy replaces the encoder readings by the commands, which come "
                              "from the commanded poses: the measurement file needs the cmd_ columns")
        with np.errstate(invalid="ignore"):
            commands = nominal.ik(meas.commanded)
        return nominal, setup, dataclasses.replace(meas, actuators=commands)
    keep = tuple(range(nominal.n_dof)) if keep is None else tuple(int(k) for k in keep)
    if len(keep) != nominal.n_dof or len(set(keep)) != len(keep) or not all(0 <= k < nominal.n_actuators for k in keep):
        raise PkmcalError(f"--keep: give {nominal.n_dof} different actuator numbers of 1..{nominal.n_actuators} "
                          f"(e.g. {','.join(str(i + 1) for i in range(nominal.n_dof))}); got "
                          f"{','.join(str(k + 1) for k in keep)}")
    sub = ActuatorSubset(nominal, keep)
    return (sub, dataclasses.replace(setup, noise=sub.noise(setup.noise)),
            dataclasses.replace(meas, actuators=np.asarray(meas.actuators)[:, list(keep)]))


def baseline_result(result, nominal: Mechanism, method: str):
    """The engine's result of the baseline fit ``method`` as a result of ``nominal``'s kind
    (the ``actuator-subset`` view unwrapped, its covariance kept; ``method`` named)."""
    mech = result.mechanism
    if method == "actuator-subset":     # the fit ran on ActuatorSubset(nominal, keep)
        base = mech.base
        names = tuple(nominal.param_names)
        sel = [i for i, n in enumerate(result.free) if n in names]
        idx = np.array([names.index(result.free[i]) for i in sel], dtype=int)
        cov = embed(np.asarray(result.covariance)[np.ix_(sel, sel)], idx, len(names)) if sel else None
        mech = base.with_params(base.params, covariance=cov)
    return dataclasses.replace(result, mechanism=mech, method=method)


def identify_by_method(nominal: Mechanism, setup: MeasurementSetup, measurements, method: str | None = None,
                       keep=None, **options):
    """:func:`~pkmcal.identification.engine.identify` by ``method``, or, for a baseline of
    :data:`BASELINES`, the engine's ``projection`` fit on the inputs the baseline changes
    (:func:`baseline_inputs`; ``keep`` the actuators of ``actuator-subset``, 0-based) returned
    as a result of ``nominal``'s kind (:func:`baseline_result`). ``options``: the engine's."""
    from pkmcal.identification.engine import identify

    if method not in BASELINES:
        if keep is not None:
            raise PkmcalError("--keep selects the actuators of --method actuator-subset; use them together")
        return identify(nominal, setup, measurements, method=method, **options)
    machine, fit_setup, data = baseline_inputs(method, nominal, setup, measurements, keep)
    return baseline_result(identify(machine, fit_setup, data, method="projection", **options), nominal, method)
