"""The list of built-in machines: names, kinds and one-line descriptions, as plain text.

``pkmcal machines`` prints it without importing NumPy or a mechanism module; the machines
themselves are built on first use by :mod:`pkmcal.mechanisms.library`, which takes its
descriptions from here (one source), and a test checks that each built machine has the
kind listed.
"""

from __future__ import annotations

#: name → (kind, description), in the order ``pkmcal machines`` lists them.
BUILTIN_CATALOGUE: dict[str, tuple[str, str]] = {
    "stewart-prototype": ("6-UPS", "paper 2 prototype, Table 3 (default machine)"),
    "stewart-prototype-real": ("6-UPS", "paper 2 prototype with Table 4 deviations"),
    "planar-2dof-3act": ("planar-2dof-3act", "paper 3 case 1: 2-dof planar, 3 rotary actuators (redundant)"),
    "planar-3dof-4act": ("planar-3dof-4act", "paper 3 case 2: 3-dof planar, 4 linear actuators (redundant)"),
    "kossel-mini": ("linear-delta", "linear delta printer, Marlin's Kossel Mini example configuration"),
    "delta-picker": ("rotary-delta", "rotary pick-and-place delta, illustrative dimensions"),
    "servo-stewart": ("6-RSS", "rotary (servo) Stewart platform, illustrative hobby dimensions"),
    "hexaslide": ("6-PUS", "sliding-joint hexapod on six vertical rails, illustrative dimensions"),
}

#: The generator of symmetric hexapods, ``symmetric:KEY=VALUE,...``.
SYMMETRIC_PREFIX = "symmetric:"
SYMMETRIC_KIND = "6-UPS"
SYMMETRIC_DESCRIPTION = ("symmetric 6-6/3-6 hexapod generator; keys: base_radius, platform_radius, base_separation, "
                         "platform_separation (deg), phase (deg), offset, stroke, u_joint_tilt, s_joint_tilt (deg), "
                         "leg_diameter")

__all__ = ["BUILTIN_CATALOGUE", "SYMMETRIC_DESCRIPTION", "SYMMETRIC_KIND", "SYMMETRIC_PREFIX"]
