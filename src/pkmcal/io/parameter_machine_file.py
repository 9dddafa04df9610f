"""The generic machine file of a family without a schema of its own: every kinematic
parameter by name, units from the mechanism's declarations (issue 12 item 2)::

    kind: 6-XYZ                       # the mechanism's kind
    name: my-machine
    description: one line             # optional
    parameters: {s1.x: 98.48, beta_1: -100, ...}   # all of them; mm, degrees where param_is_angle
    limits: {motor_range: [-60, 60]}  # optional: the class's limit_keywords (degrees where declared angles)
    home: {x: 0, y: 0, z: 172.77, a: 0, b: 0, c: 0}   # optional; pose names, degrees where pose_is_angle
    workspace: {x: [-20, 20], ...}    # optional planning box
    uncertainty: {...}                # written by 'pkmcal identify' (std in the same file units)
    calibration: {...}
    setup: {...}

A family is registered for this layout by one line in :data:`pkmcal.registry.PARAMETER_FILE_KINDS`
(kind → ``"module:Class"``, imported when a file of that kind is first read). The class is
built as ``Class(name=, rho=, home=, workspace=, covariance=, description=, metadata=,
**limits)`` and declares :attr:`~pkmcal.mechanisms.base.Mechanism.limit_keywords`; its
``rho``, ``home``, ``workspace`` and limit attributes are written back. Angles are converted
from the declared flags (:func:`~pkmcal.io._yaml.deg_to_rad`, :func:`~pkmcal.io._yaml.rad_to_deg_text`):
a save/load round trip is bit-exact.
"""

from __future__ import annotations

import difflib
from importlib import import_module
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import StrictStr, ValidationError

from pkmcal.errors import InputFileError, PkmcalError, one_line
from pkmcal.io._yaml import FlowList, RawFloat, deg_to_rad, rad_to_deg_text
from pkmcal.io.machine_file import (
    Deg,
    DegRange,
    Description,
    MachineKind,
    Name,
    UncertaintySpec,
    _covariance_from_spec,
    _line_of,
    _metadata_from_spec,
    _metadata_to_file,
    _Model,
    _uncertainty_to_file,
    _validation_error,
    add_machine_kind,
)


class ParameterFile(_Model):
    """The keys of the generic layout (module docstring)."""

    kind: StrictStr
    name: Name | None = None
    description: Description | None = None
    parameters: dict[StrictStr, Deg]
    limits: dict[StrictStr, Deg | DegRange] | None = None
    home: dict[StrictStr, Deg] | None = None
    workspace: dict[StrictStr, DegRange] | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None


def named_keys(path, lines, section: str, given: dict, names: tuple[str, ...], what: str, required: bool) -> None:
    """Every key of the mapping ``section`` is one of ``names`` (else an error with the
    closest name and the line); with ``required``, every name is given."""
    unknown = [k for k in given if k not in names]
    if unknown:
        close = difflib.get_close_matches(unknown[0], names, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise InputFileError(path, f"{section}.{unknown[0]}: unknown {what}{hint}; the machine's {what}s are "
                                   f"{', '.join(names)}", line=_line_of((section, unknown[0]), lines))
    missing = [n for n in names if n not in given]
    if required and missing:
        raise InputFileError(path, f"{section}: missing {', '.join(missing)}; give every {what} "
                                   f"({', '.join(names)}; mm, angles in degrees)", line=_line_of((section,), lines))


def _internal(v, angle: bool):
    """A file value (a number or a pair) in internal units."""
    if isinstance(v, tuple):
        return tuple(_internal(x, angle) for x in v)
    return deg_to_rad(v) if angle else float(v)


def _written(v, angle: bool):
    """An internal value (a number or a sequence) as written: degree texts for angles."""
    if np.ndim(v):
        return FlowList(_written(x, angle) for x in np.asarray(v, dtype=float))
    return RawFloat(rad_to_deg_text(float(v))) if angle else float(v)


def _class(target: str) -> type:
    module, _, name = target.partition(":")
    return getattr(import_module(module), name)


def parameter_file_kind(kind: str, target: str) -> MachineKind:
    """The :class:`MachineKind` of the generic layout for the mechanism class ``target``
    (``"module:Class"``, imported on first use) of kind ``kind``."""

    def read(path: object, data: dict, lines: dict[tuple, int]):
        try:
            spec = ParameterFile.model_validate(data)
        except ValidationError as exc:
            raise _validation_error(path, exc, lines, ParameterFile) from None
        cls = _class(target)
        names, p_ang = tuple(cls.PARAM_NAMES), tuple(cls.PARAM_IS_ANGLE)
        named_keys(path, lines, "parameters", spec.parameters, names, "parameter", required=True)
        kw: dict[str, Any] = {"rho": np.array([_internal(spec.parameters[n], a) for n, a in zip(names, p_ang)])}
        poses, pose_ang = tuple(cls.pose_names), tuple(cls.pose_is_angle)
        if spec.home is not None:
            named_keys(path, lines, "home", spec.home, poses, "pose coordinate", required=True)
            kw["home"] = np.array([_internal(spec.home[n], a) for n, a in zip(poses, pose_ang)])
        if spec.workspace is not None:
            named_keys(path, lines, "workspace", spec.workspace, poses, "pose coordinate", required=True)
            kw["workspace"] = np.array([_internal(spec.workspace[n], a) for n, a in zip(poses, pose_ang)])
        limits = dict(cls.limit_keywords)
        if spec.limits is not None:
            named_keys(path, lines, "limits", spec.limits, tuple(limits), "limit", required=False)
            kw.update({k: _internal(v, limits[k]) for k, v in spec.limits.items()})
        if spec.uncertainty is not None:
            kw["covariance"] = _covariance_from_spec(path, spec.uncertainty, lines, names, p_ang)
        name = spec.name if spec.name is not None else one_line(Path(str(path)).stem)
        try:
            return cls(name=name, description=spec.description or "", metadata=_metadata_from_spec(spec), **kw)
        except PkmcalError as exc:
            raise InputFileError(path, str(exc)) from None

    def write(m) -> dict:
        out: dict[str, Any] = {"kind": m.kind, "name": m.name}
        if m.description:
            out["description"] = m.description
        out["parameters"] = {n: _written(v, a) for n, v, a in zip(m.param_names, m.params, m.param_is_angle)}
        if m.limit_keywords:
            out["limits"] = {k: _written(getattr(m, k), a) for k, a in m.limit_keywords.items()}
        out["home"] = {n: _written(v, a) for n, v, a in zip(m.pose_names, m.home_pose, m.pose_is_angle)}
        if m.workspace is not None:
            out["workspace"] = {n: _written(row, a) for n, row, a in zip(m.pose_names, m.workspace, m.pose_is_angle)}
        if m.covariance is not None:
            out["uncertainty"] = _uncertainty_to_file(m.covariance, m.param_names, m.param_is_angle)
        out.update(_metadata_to_file(m.metadata))
        return out

    return MachineKind(mechanism_kind=kind, file_kinds=(kind,), read=read, write=write)


def register_parameter_kind(kind: str, target: str) -> MachineKind:
    """Register ``kind`` for the generic layout (:func:`parameter_file_kind`)."""
    return add_machine_kind(parameter_file_kind(kind, target))


__all__ = ["ParameterFile", "named_keys", "parameter_file_kind", "register_parameter_kind"]
