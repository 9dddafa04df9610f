"""Machine files of the redundantly actuated planar machines (paper 3 §3, case 1 and 2).

Registered with :func:`pkmcal.io.machine_file.register_machine_kind` as the kinds
``planar-2dof-3act`` (:class:`~pkmcal.mechanisms.planar.Planar2Dof3Act`) and
``planar-3dof-4act`` (:class:`~pkmcal.mechanisms.planar.Planar3Dof4Act`)::

    kind: planar-3dof-4act
    name: my-machine
    parameters: {L3: 230.0, y1: 0.0, y2: 460.0, alpha1: 0.0, alpha2: 0.0,    # mm, degrees
                 rho11: 340.0, ..., dq1: 0.0, ..., dq4: 0.0}
    home: {x: 0.0, y: 230.0, phi: 0.0}                 # optional; mm, degrees
    workspace: {x: [-100, 100], y: [190, 270], phi: [-25, 25]}   # optional
    limits: {min_leg_angle: 15}                        # degrees (case 1: min_transmission)
    uncertainty: {parameters: [...], std: {...}, correlation: [...], covariance: [...]}
    calibration: {...}                                 # written by 'pkmcal identify'

Every parameter is given by name (see ``pkmcal machines``); angle parameters
(:attr:`~pkmcal.mechanisms.planar.PlanarMechanism.param_is_angle`: the way directions α_i
and the encoder offsets dq_i of rotary actuators) are degrees, lengths and linear encoder
offsets mm. In ``uncertainty``, ``std`` is in the same file units (degrees for angle
parameters) and the exact ``covariance`` in internal units (mm², mm·rad, rad²). Omitted
``home``, ``workspace`` and ``limits`` take the built-in machine's values. Floats are
written exactly (:mod:`pkmcal.io._yaml`), so a save/load round trip is bit-exact.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import StrictStr, ValidationError

from pkmcal.errors import InputFileError, PkmcalError, one_line
from pkmcal.io._yaml import FlowList, RawFloat, deg_to_rad, rad_to_deg_text
from pkmcal.io.limits import magnitude_problem
from pkmcal.io.machine_file import (
    Deg,
    DegRange,
    Description,
    Name,
    UncertaintySpec,
    _covariance_from_spec,
    _line_of,
    _metadata_from_spec,
    _metadata_to_file,
    _Model,
    _uncertainty_to_file,
    _validation_error,
    register_machine_kind,
)
from pkmcal.io.parameter_machine_file import named_keys
from pkmcal.mechanisms.planar import Planar2Dof3Act, Planar3Dof4Act, PlanarMechanism, planar_2dof_3act, planar_3dof_4act


class _PlanarLimits(_Model):
    min_transmission: Deg | None = None
    min_leg_angle: Deg | None = None


class _PlanarFile(_Model):
    kind: Literal["planar-2dof-3act", "planar-3dof-4act"]
    name: Name | None = None
    description: Description | None = None
    parameters: dict[StrictStr, Deg]
    home: dict[StrictStr, Deg] | None = None
    workspace: dict[StrictStr, DegRange] | None = None
    limits: _PlanarLimits | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None


#: kind → (class, factory of the built-in machine, its limit field)
_PLANAR = {
    "planar-2dof-3act": (Planar2Dof3Act, planar_2dof_3act, "min_transmission"),
    "planar-3dof-4act": (Planar3Dof4Act, planar_3dof_4act, "min_leg_angle"),
}


def _value(v: float, angle: bool) -> float:
    return deg_to_rad(v) if angle else float(v)


def _planar_from_file(path: object, data: dict, lines: dict[tuple, int]) -> PlanarMechanism:
    try:
        spec = _PlanarFile.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(path, exc, lines, _PlanarFile) from None
    cls, factory, limit_key = _PLANAR[spec.kind]
    ref = factory()
    names, p_ang = ref.param_names, ref.param_is_angle
    named_keys(path, lines, "parameters", spec.parameters, names, "parameter", required=True)
    for n, a in zip(names, p_ang):
        problem = None if a else magnitude_problem(float(spec.parameters[n]), "mm")
        if problem is not None:
            raise InputFileError(path, f"parameters.{n}: {problem}", line=_line_of(("parameters", n), lines))
    rho = np.array([_value(spec.parameters[n], a) for n, a in zip(names, p_ang)])
    home = ref.home
    if spec.home is not None:
        named_keys(path, lines, "home", spec.home, ref.pose_names, "pose coordinate", required=True)
        home = np.array([_value(spec.home[n], a) for n, a in zip(ref.pose_names, ref.pose_is_angle)])
    workspace = ref.workspace
    if spec.workspace is not None:
        named_keys(path, lines, "workspace", spec.workspace, ref.pose_names, "pose coordinate", required=True)
        workspace = np.array([[_value(v, a) for v in spec.workspace[n]] for n, a in zip(ref.pose_names, ref.pose_is_angle)])
    kw: dict[str, Any] = {}
    if spec.limits is not None:
        other = "min_leg_angle" if limit_key == "min_transmission" else "min_transmission"
        if getattr(spec.limits, other) is not None:
            raise InputFileError(path, f"limits.{other}: not a limit of a {spec.kind} machine; its limit is "
                                       f"{limit_key} (degrees)", line=_line_of(("limits", other), lines))
        v = getattr(spec.limits, limit_key)
        if v is not None:
            if not 0 < v < 90:
                raise InputFileError(path, f"limits.{limit_key}: {float(v)!r}° is not an angle in (0, 90) degrees",
                                     line=_line_of(("limits", limit_key), lines))
            kw[limit_key] = deg_to_rad(v)
    covariance = None
    if spec.uncertainty is not None:
        covariance = _covariance_from_spec(path, spec.uncertainty, lines, names, p_ang)
    metadata = _metadata_from_spec(spec)
    name = spec.name if spec.name is not None else one_line(Path(str(path)).stem)
    try:
        machine = cls(name=name, rho=rho, home=home, workspace=workspace,
                      description=ref.description if spec.description is None else spec.description,
                      covariance=covariance, metadata=metadata, **kw)
    except PkmcalError as exc:
        raise InputFileError(path, str(exc)) from None
    problem = machine.parameter_problem()
    if problem is not None:
        raise InputFileError(path, f"parameters.{problem[0]}: {problem[1]}",
                             line=_line_of(("parameters", problem[0]), lines))
    if not np.all(np.isfinite(machine.ik(machine.home))):
        raise InputFileError(path, f"home: the machine cannot reach its home pose ({machine.summary().splitlines()[0]}); "
                                   "check the parameters or give 'home:'", line=_line_of(("home",), lines))
    return machine


def _num(v: float, angle: bool):
    return RawFloat(rad_to_deg_text(v)) if angle else float(v)


def _planar_to_file(m: PlanarMechanism) -> dict:
    kind = m.kind
    _, factory, limit_key = _PLANAR[kind]
    ref = factory()
    out: dict[str, Any] = {"kind": kind, "name": m.name}
    if m.description:
        out["description"] = m.description
    out["parameters"] = {n: _num(v, a) for n, v, a in zip(m.param_names, m.rho, m.param_is_angle)}
    out["home"] = {n: _num(v, a) for n, v, a in zip(m.pose_names, m.home, m.pose_is_angle)}
    out["workspace"] = {n: FlowList(_num(v, a) for v in row)
                        for n, row, a in zip(m.pose_names, m.workspace, m.pose_is_angle)}
    lim = getattr(m, limit_key)
    if lim != getattr(ref, limit_key):
        out["limits"] = {limit_key: RawFloat(rad_to_deg_text(lim))}
    if m.covariance is not None:
        out["uncertainty"] = _uncertainty_to_file(m.covariance, m.param_names, m.param_is_angle)
    out.update(_metadata_to_file(m.metadata))
    return out


for _kind, (_cls, _, _) in _PLANAR.items():
    register_machine_kind(_kind, _planar_from_file, _cls, _planar_to_file)
