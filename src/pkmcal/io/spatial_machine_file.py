"""What the machine files of the six-pose hexapod kinds (``6-RSS``, ``6-PUS``) share: the
common keys once (:class:`SpatialFile`: ``kind``, ``name``, ``description``, exactly six
``legs``, ``limits``, ``home``, ``workspace``, ``uncertainty``, ``calibration``,
``metadata``, the identified ``setup``; a kind's schema subclasses it with its leg and limit models), the optional
``home`` pose, ``workspace`` box and ``uncertainty`` read into the mechanism's keyword
arguments and written back exactly (mm, degrees), and the head and tail of the written
mapping (:func:`file_head`, :func:`file_tail`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from pydantic import StrictStr, ValidationError, field_validator

from pkmcal.errors import one_line
from pkmcal.io._yaml import FlowList, RawFloat, deg_to_rad, rad_to_deg_text
from pkmcal.io.machine_file import (
    Description,
    Name,
    PoseSpec,
    UncertaintySpec,
    WorkspaceSpec,
    _covariance_from_spec,
    _metadata_from_spec,
    _metadata_to_file,
    _Model,
    _uncertainty_to_file,
    _validation_error,
)

N_LEGS = 6


def six_legs(v, kind: str):
    """The ``legs`` list validator: exactly six entries, in order."""
    if isinstance(v, list) and len(v) != N_LEGS:
        raise ValueError(f"{len(v)} legs given, a {kind} hexapod needs exactly {N_LEGS}; list one entry per leg, "
                         f"legs 1 to {N_LEGS} in order")
    return v


class SpatialFile(_Model):
    """The keys every six-legged hexapod file has, in the order they are checked; a kind's
    schema sets ``family`` and narrows ``kind`` (a ``Literal``), ``legs`` and ``limits``."""

    family: ClassVar[str] = "spatial"
    kind: StrictStr
    name: Name | None = None
    description: Description | None = None
    legs: list[Any]
    limits: Any | None = None
    home: PoseSpec | None = None
    workspace: WorkspaceSpec | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None

    @field_validator("legs", mode="before")
    @classmethod
    def _six_legs(cls, v):
        return six_legs(v, cls.family)


def read_spec(schema: type[SpatialFile], path: object, data: dict, lines: dict[tuple, int]) -> SpatialFile:
    """``data`` validated by ``schema``; an :class:`InputFileError` naming the key and line."""
    try:
        return schema.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(path, exc, lines, schema) from None


def common_kwargs(path: object, spec: SpatialFile, lines: dict[tuple, int], names, is_angle) -> dict[str, Any]:
    """The keyword arguments every hexapod kind takes from its file: ``name`` (default the
    file's stem), ``description``, ``metadata`` and :func:`pose_extras`."""
    return {"name": spec.name if spec.name is not None else one_line(Path(str(path)).stem),
            "description": spec.description or "", "metadata": _metadata_from_spec(spec),
            **pose_extras(path, spec, lines, names, is_angle)}


def file_head(m) -> dict[str, Any]:
    """The first keys written: ``kind``, ``name`` and ``description`` (when there is one)."""
    out: dict[str, Any] = {"kind": m.kind, "name": m.name}
    if m.description:
        out["description"] = m.description
    return out


def file_tail(m, names, is_angle) -> dict[str, Any]:
    """The last keys written: :func:`pose_extras_to_file` and the metadata blocks."""
    return {**pose_extras_to_file(m, names, is_angle), **_metadata_to_file(m.metadata)}


def pose_extras(path: object, spec, lines: dict[tuple, int], names, is_angle) -> dict[str, Any]:
    """``home``, ``workspace`` and ``covariance`` keyword arguments (internal units) of the
    file's optional keys of those names (``uncertainty`` for the covariance)."""
    kw: dict[str, Any] = {}
    if spec.home is not None:
        h = spec.home
        kw["home"] = np.array([h.x, h.y, h.z, deg_to_rad(h.a), deg_to_rad(h.b), deg_to_rad(h.c)])
    if spec.workspace is not None:
        w = spec.workspace
        kw["workspace"] = np.array([list(w.x), list(w.y), list(w.z), [deg_to_rad(v) for v in w.a],
                                    [deg_to_rad(v) for v in w.b], [deg_to_rad(v) for v in w.c]], dtype=float)
    if spec.uncertainty is not None:
        kw["covariance"] = _covariance_from_spec(path, spec.uncertainty, lines, names, is_angle)
    return kw


def degrees(v: float) -> RawFloat:
    """An angle (rad) as its exact degree text."""
    return RawFloat(rad_to_deg_text(v))


def pose_extras_to_file(m, names, is_angle) -> dict[str, Any]:
    """``home`` (always: it is exact), ``workspace`` and ``uncertainty`` (when set) of ``m``."""
    out: dict[str, Any] = {"home": {**{k: float(v) for k, v in zip("xyz", m.home[:3])},
                                    **{k: degrees(v) for k, v in zip("abc", m.home[3:])}}}
    if m.workspace is not None:
        ws = {k: FlowList(float(v) for v in m.workspace[i]) for i, k in enumerate("xyz")}
        ws.update({k: FlowList(degrees(v) for v in m.workspace[3 + i]) for i, k in enumerate("abc")})
        out["workspace"] = ws
    if m.covariance is not None:
        out["uncertainty"] = _uncertainty_to_file(m.covariance, names, is_angle)
    return out


def leg_line(exc_text: str, lines: dict[tuple, int]):
    """The line of ``legs[i].<key>`` named by a mechanism's "<key>_<i> ..." message, or None."""
    from pkmcal.io.machine_file import _line_of

    param = exc_text.split(" ", 1)[0]
    if "_" in param and param.rsplit("_", 1)[-1].isdigit():
        key, leg = param.rsplit("_", 1)
        return _line_of(("legs", int(leg) - 1, key), lines)
    return None


__all__ = ["SpatialFile", "common_kwargs", "degrees", "file_head", "file_tail", "leg_line", "pose_extras",
           "pose_extras_to_file", "read_spec", "six_legs"]
