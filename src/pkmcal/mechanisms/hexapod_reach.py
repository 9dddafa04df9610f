"""What a 6-UPS hexapod's joint geometry reaches, whatever its configured limits allow.

A controller's configuration may give limits far looser than any machine: LinuxCNC's own
hexapod sample (``configs/sim/axis/vismach/hexapod-sim/hexapod.ini``) lets every strut
run from −1000 to 1000 inch on a machine whose struts are 29.75 inch (755.6 mm) long at
home, and LinuxCNC has no setting for joint tilts at all. Planning on such limits searched
a box of metres and thousands of degrees (x = 3938 mm, a = −9450° on that 673 mm machine)
in which almost no pose is one the machine can take. Two bounds hold for any hexapod built
of ordinary parts; :func:`reachable_machine` (:meth:`Hexapod.within_geometry
<pkmcal.mechanisms.hexapod.Hexapod.within_geometry>`) clips the machine's limits to them,
with a note naming each limit that was looser; planning plans on the clipped machine
(:func:`pkmcal.planning.plan.plan_poses`) and ``pkmcal import linuxcnc`` reports a strut range
beyond the first bound:

* **strut length** within [L_h / k, k·L_h], k = :data:`STRUT_RATIO` = 2, L_h the leg's
  length at the home pose. A single-stage strut (a screw or a rod in its housing) cannot
  extend by more than its retracted length, L_max < 2·L_min, and its home length lies
  between the two, so L_min > L_max / 2 ≥ L_h / 2 and L_max < 2·L_min ≤ 2·L_h, wherever
  home lies in the stroke. (Multi-stage telescopic struts, the one kind beyond, are planned
  within this range too.)
* **joint tilt** below :data:`MAX_TILT` = 90° at the U and S joints (the angle between the
  leg and the joint's axis, as :class:`~pkmcal.mechanisms.hexapod.HexapodLimits` measures
  it): a leg tilted further passes through the base or the platform its joint is mounted
  on.

A hexapod whose limits lie within both is returned as it is (every built-in hexapod: the
prototype's struts run 305–355 mm about 330 mm at home, its tilt limits are 45° and 29°).
Other machine kinds keep their limits (:meth:`Mechanism.within_geometry
<pkmcal.mechanisms.base.Mechanism.within_geometry>`: theirs are their geometry's).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pkmcal.mechanisms.hexapod import Hexapod

#: A single-stage strut's longest length over its shortest is below this (module docstring).
STRUT_RATIO = 2.0
#: Largest joint tilt (rad) of a leg that does not pass through its own mounting plate.
MAX_TILT = math.pi / 2


def strut_range(mechanism: Hexapod) -> np.ndarray:
    """The strut lengths (6, 2) [min, max] (mm) that the geometry allows: [L_h / k, k·L_h]
    with L_h the leg lengths at the home pose (module docstring)."""
    home_lengths = mechanism.leg_lengths(np.asarray(mechanism.home_pose, dtype=float)[None, :])[0]
    return np.stack([home_lengths / STRUT_RATIO, home_lengths * STRUT_RATIO], axis=1)


def loose_stroke_note(mechanism: Hexapod) -> tuple[np.ndarray, str | None]:
    """(the stroke (6, 2) clipped to :func:`strut_range`, in reading units; a note naming the
    looser limit and where it was set (:meth:`~pkmcal.mechanisms.base.Mechanism.limit_source`),
    or None when the stroke is within the range). A leg whose stroke does not overlap the
    range is left as it is (its home pose is then outside its stroke, which planning reports)."""
    lengths = mechanism.offset[:, None] + mechanism.gains[:, None] * np.asarray(mechanism.stroke, dtype=float)
    allowed = strut_range(mechanism)
    lo, hi = np.maximum(lengths[:, 0], allowed[:, 0]), np.minimum(lengths[:, 1], allowed[:, 1])
    clip = (lo < hi) & ((lo > lengths[:, 0]) | (hi < lengths[:, 1]))
    stroke = np.array(mechanism.stroke, dtype=float)
    if not clip.any():
        return stroke, None
    stroke[clip, 0] = (lo[clip] - mechanism.offset[clip]) / mechanism.gains[clip]
    stroke[clip, 1] = (hi[clip] - mechanism.offset[clip]) / mechanism.gains[clip]
    legs = ", ".join(str(int(i) + 1) for i in np.flatnonzero(clip))
    source = mechanism.limit_source("stroke", "the legs' 'stroke:' in the machine file")
    home = mechanism.leg_lengths(np.asarray(mechanism.home_pose, dtype=float)[None, :])[0][clip]
    note = (f"the strut range of legs {legs} ({lengths[clip, 0].min():.6g} to {lengths[clip, 1].max():.6g} mm, "
            f"{source}) is beyond what struts {home.min():.4g}"
            f"{'' if np.ptp(home) < 0.05 else f'-{home.max():.4g}'} mm long at home reach: a single-stage strut "
            f"runs between 1/{STRUT_RATIO:g} and {STRUT_RATIO:g} times its home length "
            f"({allowed[clip, 0].min():.4g} to {allowed[clip, 1].max():.4g} mm); pkmcal plan and info keep the "
            "struts within that; set the real strut range")
    return stroke, note


def reachable_machine(mechanism: Hexapod) -> tuple[Hexapod, tuple[str, ...]]:
    """(``mechanism`` with its stroke and joint tilt limits clipped to what its geometry
    reaches, one note per limit that was looser): module docstring. The same machine and no
    notes when it is within both bounds (:meth:`Hexapod.within_geometry`)."""
    notes = []
    stroke, note = loose_stroke_note(mechanism)
    if note is not None:
        notes.append(note)
    lim = mechanism.limits
    tilts = {name: MAX_TILT for name in ("u_joint_tilt", "s_joint_tilt")
             if getattr(lim, name) is None or getattr(lim, name) > MAX_TILT}
    if tilts:
        said = [f"{'U (base)' if n[0] == 'u' else 'S (platform)'} joint "
                + ("none" if getattr(lim, n) is None else f"{math.degrees(getattr(lim, n)):.4g}°") for n in tilts]
        notes.append(f"joint tilt limits beyond 90° ({', '.join(said)}; 'limits: {', '.join(tilts)}' in the machine "
                     "file, LinuxCNC has no such setting): pkmcal plan and info keep every leg within 90° of its "
                     "joints' axes (a leg beyond passes through the plate its joint is mounted on); add the joints' "
                     "real limits")
    if note is None and not tilts:
        return mechanism, ()
    return replace(mechanism, stroke=stroke, limits=replace(lim, **tilts)), tuple(notes)


__all__ = ["MAX_TILT", "STRUT_RATIO", "loose_stroke_note", "reachable_machine", "strut_range"]
