"""Machine files of rotary hexapods: ``kind: 6-RSS``
(:class:`~pkmcal.mechanisms.rss_hexapod.RSSHexapod`), registered with
:func:`pkmcal.io.machine_file.register_machine_kind`::

    kind: 6-RSS
    name: servo-stewart
    legs:                 # exactly 6; lengths mm, angles degrees; tilt and zero default 0
      - {pivot: [98.48, -17.36, 0], beta: -100, crank: 25, rod: 180, platform: [45, -53.62, 0]}
      - ...
    limits: {motor_range: [-60, 60], max_joint_angle: 60}   # crank angles φ, rod cone; degrees
    home: {x: 0, y: 0, z: 172.77, a: 0, b: 0, c: 0}         # optional (default: the cranks level on average)
    workspace: {x: [-20, 20], ...}                          # optional planning box (mm, degrees)
    uncertainty: {...}                                      # written by 'pkmcal identify'

The parameters are those of the module docstring (``s<i>.x``, ``beta_<i>``, ``crank_<i>``,
``a<i>.x``, ``zero_<i>``, ...). Floats are written exactly (:mod:`pkmcal.io._yaml`): a
save/load round trip is bit-exact.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.io._yaml import FlowList, deg_to_rad
from pkmcal.io.machine_file import Deg, DegRange, Length, Vec3, _Model, register_machine_kind
from pkmcal.io.spatial_machine_file import SpatialFile, common_kwargs, degrees, file_head, file_tail, leg_line, read_spec
from pkmcal.mechanisms import rss_hexapod as rss


class _Leg(_Model):
    pivot: Vec3
    beta: Deg
    tilt: Deg = 0.0
    crank: Length
    rod: Length
    platform: Vec3
    zero: Deg = 0.0


class _Limits(_Model):
    motor_range: DegRange | None = None
    max_joint_angle: Deg | None = None


class _File(SpatialFile):
    family = "6-RSS"
    kind: Literal["6-RSS"]
    legs: list[_Leg]
    limits: _Limits | None = None


def _from_file(path: object, data: dict, lines: dict[tuple, int]) -> rss.RSSHexapod:
    spec = read_spec(_File, path, data, lines)
    rho = np.array([v for leg in spec.legs for v in (*leg.pivot, deg_to_rad(leg.beta), deg_to_rad(leg.tilt),
                                                    float(leg.crank), float(leg.rod), *leg.platform,
                                                    deg_to_rad(leg.zero))], dtype=float)
    kw: dict[str, Any] = {}
    if spec.limits is not None:
        if spec.limits.motor_range is not None:
            kw["motor_range"] = tuple(deg_to_rad(v) for v in spec.limits.motor_range)
        if spec.limits.max_joint_angle is not None:
            kw["max_joint_angle"] = deg_to_rad(spec.limits.max_joint_angle)
    kw.update(common_kwargs(path, spec, lines, rss.PARAM_NAMES, rss.PARAM_IS_ANGLE))
    try:
        return rss.RSSHexapod(rho=rho, **kw)
    except PkmcalError as exc:
        text = str(exc).split(": ", 1)[-1]
        raise InputFileError(path, f"legs: {text}", line=leg_line(text, lines)) from None


def _to_file(m: rss.RSSHexapod) -> dict:
    out = file_head(m)
    g = rss._legs(m.rho)
    deg = degrees
    legs = []
    for i in range(rss.N_LEGS):
        leg: dict[str, Any] = {"pivot": FlowList(float(v) for v in g["S"][i]), "beta": deg(g["beta"][i])}
        if g["tilt"][i] != 0:
            leg["tilt"] = deg(g["tilt"][i])
        leg.update({"crank": float(g["crank"][i]), "rod": float(g["rod"][i]),
                    "platform": FlowList(float(v) for v in g["a"][i])})
        if g["zero"][i] != 0:
            leg["zero"] = deg(g["zero"][i])
        legs.append(leg)
    out["legs"] = legs
    out["limits"] = {"motor_range": FlowList(deg(v) for v in m.motor_range), "max_joint_angle": deg(m.max_joint_angle)}
    out.update(file_tail(m, rss.PARAM_NAMES, rss.PARAM_IS_ANGLE))
    return out


register_machine_kind("6-RSS", _from_file, rss.RSSHexapod, _to_file)
