"""Machine files of the deltas: ``kind: linear-delta``
(:class:`~pkmcal.mechanisms.linear_delta.LinearDelta`) and ``kind: rotary-delta``
(:class:`~pkmcal.mechanisms.rotary_delta.RotaryDelta`), registered with
:func:`pkmcal.io.machine_file.register_machine_kind`::

    kind: linear-delta
    name: kossel-mini
    towers:                     # lengths mm, angles degrees; lean_* default 0
      a: {angle: 210, radius: 105.2, arm: 215, endstop: 250}
      b: {angle: 330, radius: 105.2, arm: 215, endstop: 250}
      c: {angle: 90,  radius: 105.2, arm: 215, endstop: 250, lean_radial: 0.1}
    tool: [0, 0, 0]             # optional: the nozzle from the effector joints' centre, mm
    reading_reference: [437.5, 437.5, 437.5]   # optional (see below)
    limits: {print_radius: 90, min_z: 0, min_arm_angle: 20, travel: 400}
    uncertainty: {...}          # written by 'pkmcal identify'
    calibration: {...}

    kind: rotary-delta
    name: delta-picker
    arms:                       # lengths mm, angles degrees; zero, axis_* default 0
      a: {angle: 90,  radius: 150, height: 0, upper: 350, forearm: 800}
      b: {angle: 210, radius: 150, height: 0, upper: 350, forearm: 800}
      c: {angle: 330, radius: 150, height: 0, upper: 350, forearm: 800}
    limits: {motor_range: [-40, 100], max_joint_angle: 60, workspace_radius: 400,
             z_range: [-1000, -500]}

The parameters are those of the modules' docstrings, named ``<parameter>_<tower>`` (e.g.
``arm_b``) in ``uncertainty`` and on the command line. A linear delta's
``reading_reference`` is the switch reading of each carriage in the firmware configuration
that the machine's readings (``lambda1..3``) refer to: a calibrated machine keeps its
nominal machine's, so that its readings mean what the firmware showed; omitted, the
machine's own (its readings are then its firmware's stepper positions). Floats are written
exactly (:mod:`pkmcal.io._yaml`): a save/load round trip is bit-exact.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import StrictStr, ValidationError

from pkmcal.errors import InputFileError, PkmcalError, one_line
from pkmcal.io._yaml import FlowList, RawFloat, deg_to_rad, rad_to_deg_text
from pkmcal.io.machine_file import (
    Deg,
    DegRange,
    Description,
    Length,
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
from pkmcal.mechanisms import linear_delta as ld
from pkmcal.mechanisms import rotary_delta as rd


class _Tower(_Model):
    angle: Deg
    radius: Length
    arm: Length
    endstop: Length
    lean_radial: Deg = 0.0
    lean_tangential: Deg = 0.0


class _LinearLimits(_Model):
    print_radius: Length | None = None
    min_z: Length | None = None
    min_arm_angle: Deg | None = None
    travel: Length | tuple[Length, Length, Length] | None = None


class _LinearFile(_Model):
    kind: Literal["linear-delta"]
    name: Name | None = None
    description: Description | None = None
    towers: dict[Literal["a", "b", "c"], _Tower]
    tool: tuple[Length, Length, Length] | None = None
    reading_reference: tuple[Length, Length, Length] | None = None
    limits: _LinearLimits | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None


class _Arm(_Model):
    angle: Deg
    radius: Length
    height: Length
    upper: Length
    forearm: Length
    zero: Deg = 0.0
    axis_yaw: Deg = 0.0
    axis_tilt: Deg = 0.0


class _RotaryLimits(_Model):
    motor_range: DegRange | None = None
    max_joint_angle: Deg | None = None
    workspace_radius: Length | None = None
    z_range: tuple[Length, Length] | None = None


class _RotaryFile(_Model):
    kind: Literal["rotary-delta"]
    name: Name | None = None
    description: Description | None = None
    arms: dict[Literal["a", "b", "c"], _Arm]
    tool: tuple[Length, Length, Length] | None = None
    limits: _RotaryLimits | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None


def _value(v: float, angle: bool) -> float:
    return deg_to_rad(v) if angle else float(v)


def _num(v: float, angle: bool):
    return RawFloat(rad_to_deg_text(v)) if angle else float(v)


def _rho(path, lines, section: str, entries: dict, layout, tool) -> np.ndarray:
    """ρ in the layout's order (:class:`~pkmcal.mechanisms.translating.ArmLayout`) from
    the per-arm mappings of the file (degrees for angles) and the tool offset."""
    missing = [a for a in layout.arms if a not in entries]
    if missing:
        raise InputFileError(path, f"{section}: missing {', '.join(missing)}; give all three (a, b, c)",
                             line=_line_of((section,), lines))
    values = [_value(getattr(entries[a], p), p in layout.angles) for a in layout.arms for p in layout.params]
    return np.array(values + [float(v) for v in (tool or (0.0, 0.0, 0.0))])


def _arm_table(rho: np.ndarray, layout) -> dict:
    """The per-arm mappings of the file (inverse of :func:`_rho`; angles as exact degree text)."""
    g = layout.split(rho)
    return {a: {p: _num(g[p][i], p in layout.angles) for p in layout.params} for i, a in enumerate(layout.arms)}


def _build(path, lines, cls, kwargs: dict, section: str):
    try:
        machine = cls(**kwargs)
    except PkmcalError as exc:
        text = str(exc).split(": ", 1)[-1]
        name = text.split(" ", 1)[0]
        where = None
        if "_" in name and name.rsplit("_", 1)[-1] in ("a", "b", "c"):
            param, tower = name.rsplit("_", 1)
            where = _line_of((section, tower, param), lines)
        raise InputFileError(path, f"{section}: {text}", line=where) from None
    return machine


def _linear_from_file(path: object, data: dict, lines: dict[tuple, int]) -> ld.LinearDelta:
    try:
        spec = _LinearFile.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(path, exc, lines, _LinearFile) from None
    rho = _rho(path, lines, "towers", spec.towers, ld.LAYOUT, spec.tool)
    kw: dict[str, Any] = {}
    lim = spec.limits
    if lim is not None:
        for key in ("print_radius", "min_z"):
            if getattr(lim, key) is not None:
                kw[key] = float(getattr(lim, key))
        if lim.min_arm_angle is not None:
            kw["min_arm_angle"] = deg_to_rad(lim.min_arm_angle)
        if lim.travel is not None:
            kw["travel"] = np.broadcast_to(np.asarray(lim.travel, dtype=float), (3,)).copy()
    if spec.reading_reference is not None:
        kw["reading_reference"] = np.array(spec.reading_reference, dtype=float)
    if spec.uncertainty is not None:
        kw["covariance"] = _covariance_from_spec(path, spec.uncertainty, lines, ld.PARAM_NAMES, ld.PARAM_IS_ANGLE)
    name = spec.name if spec.name is not None else one_line(Path(str(path)).stem)
    return _build(path, lines, ld.LinearDelta, dict(name=name, rho=rho, description=spec.description or "",
                                                   metadata=_metadata_from_spec(spec), **kw), "towers")


def _linear_to_file(m: ld.LinearDelta) -> dict:
    out: dict[str, Any] = {"kind": "linear-delta", "name": m.name}
    if m.description:
        out["description"] = m.description
    rho = m.rho
    out["towers"] = _arm_table(rho, ld.LAYOUT)
    out["tool"] = FlowList(float(v) for v in rho[-3:])
    out["reading_reference"] = FlowList(float(v) for v in m.reading_reference)
    out["limits"] = {"print_radius": float(m.print_radius), "min_z": float(m.min_z),
                     "min_arm_angle": RawFloat(rad_to_deg_text(m.min_arm_angle)),
                     "travel": FlowList(float(v) for v in m.travel)}
    if m.covariance is not None:
        out["uncertainty"] = _uncertainty_to_file(m.covariance, ld.PARAM_NAMES, ld.PARAM_IS_ANGLE)
    out.update(_metadata_to_file(m.metadata))
    return out


def _rotary_from_file(path: object, data: dict, lines: dict[tuple, int]) -> rd.RotaryDelta:
    try:
        spec = _RotaryFile.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(path, exc, lines, _RotaryFile) from None
    rho = _rho(path, lines, "arms", spec.arms, rd.LAYOUT, spec.tool)
    kw: dict[str, Any] = {}
    lim = spec.limits
    if lim is not None:
        if lim.motor_range is not None:
            kw["motor_range"] = tuple(deg_to_rad(v) for v in lim.motor_range)
        if lim.max_joint_angle is not None:
            kw["max_joint_angle"] = deg_to_rad(lim.max_joint_angle)
        if lim.workspace_radius is not None:
            kw["workspace_radius"] = float(lim.workspace_radius)
        if lim.z_range is not None:
            lo, hi = (float(v) for v in lim.z_range)
            if not lo < hi:
                raise InputFileError(path, f"limits.z_range: [{lo:g}, {hi:g}] is not an interval (low, high)",
                                     line=_line_of(("limits", "z_range"), lines))
            kw["z_range"] = (lo, hi)
    if spec.uncertainty is not None:
        kw["covariance"] = _covariance_from_spec(path, spec.uncertainty, lines, rd.PARAM_NAMES, rd.PARAM_IS_ANGLE)
    name = spec.name if spec.name is not None else one_line(Path(str(path)).stem)
    return _build(path, lines, rd.RotaryDelta, dict(name=name, rho=rho, description=spec.description or "",
                                                   metadata=_metadata_from_spec(spec), **kw), "arms")


def _rotary_to_file(m: rd.RotaryDelta) -> dict:
    out: dict[str, Any] = {"kind": "rotary-delta", "name": m.name}
    if m.description:
        out["description"] = m.description
    rho = m.rho
    out["arms"] = _arm_table(rho, rd.LAYOUT)
    out["tool"] = FlowList(float(v) for v in rho[-3:])
    out["limits"] = {"motor_range": FlowList(RawFloat(rad_to_deg_text(v)) for v in m.motor_range),
                     "max_joint_angle": RawFloat(rad_to_deg_text(m.max_joint_angle)),
                     "workspace_radius": float(m.workspace_radius),
                     "z_range": FlowList(float(v) for v in m.z_range)}
    if m.covariance is not None:
        out["uncertainty"] = _uncertainty_to_file(m.covariance, rd.PARAM_NAMES, rd.PARAM_IS_ANGLE)
    out.update(_metadata_to_file(m.metadata))
    return out


register_machine_kind("linear-delta", _linear_from_file, ld.LinearDelta, _linear_to_file)
register_machine_kind("rotary-delta", _rotary_from_file, rd.RotaryDelta, _rotary_to_file)
