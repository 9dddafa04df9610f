"""What the machine files of the six-pose hexapod kinds (``6-RSS``, ``6-PUS``) share:
exactly six ``legs``, and the optional ``home`` pose, ``workspace`` box and ``uncertainty``
read into the mechanism's keyword arguments and written back exactly (mm, degrees)."""

from __future__ import annotations

from typing import Any

import numpy as np

from pkmcal.io._yaml import FlowList, RawFloat, deg_to_rad, rad_to_deg_text
from pkmcal.io.machine_file import _covariance_from_spec, _uncertainty_to_file

N_LEGS = 6


def six_legs(v, kind: str):
    """The ``legs`` list validator: exactly six entries, in order."""
    if isinstance(v, list) and len(v) != N_LEGS:
        raise ValueError(f"{len(v)} legs given, a {kind} hexapod needs exactly {N_LEGS}; list one entry per leg, "
                         f"legs 1 to {N_LEGS} in order")
    return v


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


__all__ = ["degrees", "leg_line", "pose_extras", "pose_extras_to_file", "six_legs"]
