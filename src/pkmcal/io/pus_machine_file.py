"""Machine files of sliding-joint hexapods: ``kind: 6-PUS``
(:class:`~pkmcal.mechanisms.pus_hexapod.PUSHexapod`), registered with
:func:`pkmcal.io.machine_file.register_machine_kind`::

    kind: 6-PUS
    name: hexaslide
    legs:           # exactly 6; mm and degrees; tilt_x, tilt_y, offset default 0, branch -1
      - {rail_origin: [147.72, -26.05, 0], rail: [0, 0, 1], leg: 200, platform: [45.0, -53.62, 0],
         stroke: [0, 150], branch: -1}
      - ...
    limits: {max_joint_angle: 60}
    home: {x: 0, y: 0, z: 244.37, a: 0, b: 0, c: 0}      # optional (default: mid-stroke on average)
    workspace: {x: [-20, 20], ...}                       # optional planning box (mm, degrees)

``rail`` is the nominal rail direction (fixed; normalised on load); the parameters
``tilt_x_<i>``, ``tilt_y_<i>`` tilt the rail from it (see the mechanism's docstring).
Floats are written exactly (:mod:`pkmcal.io._yaml`): a save/load round trip is bit-exact.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io._yaml import FlowList, deg_to_rad
from pkmcal.io.machine_file import Deg, Length, Vec3, _Model, register_machine_kind
from pkmcal.io.spatial_machine_file import SpatialFile, common_kwargs, degrees, file_head, file_tail, leg_line, read_spec
from pkmcal.mechanisms import pus_hexapod as pus


class _Leg(_Model):
    rail_origin: Vec3
    rail: Vec3
    tilt_x: Deg = 0.0
    tilt_y: Deg = 0.0
    leg: Length
    platform: Vec3
    offset: Length = 0.0
    stroke: tuple[Length, Length]
    branch: Literal[-1, 1] = -1


class _Limits(_Model):
    max_joint_angle: Deg | None = None


class _File(SpatialFile):
    family = "6-PUS"
    kind: Literal["6-PUS"]
    legs: list[_Leg]
    limits: _Limits | None = None


def _from_file(path: object, data: dict, lines: dict[tuple, int]) -> pus.PUSHexapod:
    spec = read_spec(_File, path, data, lines)
    legs = spec.legs
    rho = np.array([v for leg in legs for v in (*leg.rail_origin, deg_to_rad(leg.tilt_x), deg_to_rad(leg.tilt_y),
                                                float(leg.leg), *leg.platform, float(leg.offset))], dtype=float)
    kw: dict[str, Any] = {}
    if spec.limits is not None and spec.limits.max_joint_angle is not None:
        kw["max_joint_angle"] = deg_to_rad(spec.limits.max_joint_angle)
    kw.update(common_kwargs(path, spec, lines, pus.PARAM_NAMES, pus.PARAM_IS_ANGLE))
    try:
        return pus.PUSHexapod(rho=rho, rails=[leg.rail for leg in legs], stroke=[leg.stroke for leg in legs],
                              branches=[leg.branch for leg in legs], **kw)
    except PkmcalError as exc:
        text = str(exc).split(": ", 1)[-1]
        raise InputFileError(path, f"legs: {text}", line=leg_line(text, lines)) from None


def _to_file(m: pus.PUSHexapod) -> dict:
    out = file_head(m)
    g = pus._legs(m.rho)
    deg = degrees
    legs = []
    for i in range(pus.N_LEGS):
        leg: dict[str, Any] = {"rail_origin": FlowList(float(v) for v in g["O"][i]),
                               "rail": FlowList(float(v) for v in m.rails[i])}
        for key, short in (("tilt_x", "tx"), ("tilt_y", "ty")):
            if g[short][i] != 0:
                leg[key] = deg(g[short][i])
        leg.update({"leg": float(g["leg"][i]), "platform": FlowList(float(v) for v in g["a"][i])})
        if g["offset"][i] != 0:
            leg["offset"] = float(g["offset"][i])
        leg["stroke"] = FlowList(float(v) for v in m.stroke[i])
        leg["branch"] = int(m.branches[i])
        legs.append(leg)
    out["legs"] = legs
    out["limits"] = {"max_joint_angle": deg(m.max_joint_angle)}
    out.update(file_tail(m, pus.PARAM_NAMES, pus.PARAM_IS_ANGLE))
    return out


register_machine_kind("6-PUS", _from_file, pus.PUSHexapod, _to_file)
