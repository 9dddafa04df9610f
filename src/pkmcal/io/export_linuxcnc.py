"""Export a (calibrated) hexapod to LinuxCNC's ``genhexkins`` kinematics module.

genhexkins (LinuxCNC ``src/emc/kinematics/genhexkins.c``) computes, for a pose
``X Y Z A B C`` (mm, degrees), the strut lengths

    joint_N = ‖ p + R a_N − b_N ‖,     R = Rz(C) Ry(B) Rx(A)   (posemath ``pmRpyMatConvert``)

with b_N the base joints in world coordinates (HAL ``genhexkins.base.N.x|y|z``) and a_N the
platform joints in platform coordinates (``genhexkins.platform.N.x|y|z``). That is exactly
pkmcal's leg length L_i = ‖p + R a_i − b_i‖ (paper 1 eq. 1, paper 2 eq. 1) with N = i − 1 and
the same pose convention (:mod:`pkmcal.conventions`), so the joints are copied unchanged.

genhexkins' joints are strut *lengths*; pkmcal's actuator readings are λ_i = L_i − L0_i. The
leg offsets L0_i have no genhexkins pin: they enter LinuxCNC through homing, as the joint
position assigned at the home switch (``[JOINT_N] HOME_OFFSET`` in the INI file). The export
writes them, the stroke as joint limits, and the strut lengths at pkmcal's home pose as
comment lines with the INI settings they imply. See ``docs/conventions.md``.

The text is safe by construction for ``halcmd -f``, which reads a file with ``fgets`` into
a 1024-byte buffer (``MAX_CMD_LEN``) and treats ``#`` to the end of the line as a comment:
user text (the machine's name and description) only ever appears in comment lines, with
every control character escaped (:func:`pkmcal.errors.one_line`, so no newline can start a
live ``setp`` line), and is wrapped into comment lines of at most :data:`MAX_COMMENT_CHARS`
characters (< 1024 bytes even in 4-byte UTF-8, so no tail of a long line can be read as a
command).
"""

from __future__ import annotations

import numpy as np

from pkmcal import __version__
from pkmcal.conventions import poses_to_file_units
from pkmcal.errors import PkmcalError, one_line
from pkmcal.mechanisms.hexapod import Hexapod

#: HAL prefix of the genhexkins component.
HAL_PREFIX = "genhexkins"
#: Longest comment line written (characters, '# ' included): 4 × 200 bytes < halcmd's 1024.
MAX_COMMENT_CHARS = 200


def comment_lines(text: str, first: str = "# ", rest: str = "#   ") -> list[str]:
    """``text`` (one line, control characters escaped) as HAL comment lines of at most
    :data:`MAX_COMMENT_CHARS` characters: ``first`` before the first piece, ``rest`` before
    the others."""
    body = one_line(text)
    out, prefix = [], first
    while True:
        room = MAX_COMMENT_CHARS - len(prefix)
        out.append(prefix + body[:room])
        body, prefix = body[room:], rest
        if not body:
            return out


def _num(v: float) -> str:
    """Shortest text that reads back to the same double (so the export is exact)."""
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to LinuxCNC")
    return repr(v + 0.0)  # + 0.0 turns -0.0 into 0.0


def linuxcnc_hal(machine: Hexapod) -> str:
    """HAL text (``setp`` lines and comments) configuring genhexkins for ``machine``.

    ``setp genhexkins.base.N.x|y|z`` and ``setp genhexkins.platform.N.x|y|z`` for N = 0..5
    (pkmcal leg i = N + 1), values in mm written exactly (shortest round-trip decimal).
    Comment lines carry, per joint, L0_i (``HOME_OFFSET`` when the home switch is at
    reading λ = 0), the joint limits L0_i + stroke, and the strut length at the machine's
    home pose (``HOME``). Run it (``halcmd -f``, or a ``[HAL] HALFILE``) after the HAL file
    that loads genhexkins (``loadrt genhexkins``).
    """
    if not isinstance(machine, Hexapod):
        raise PkmcalError(
            f"LinuxCNC export supports 6-UPS hexapods (genhexkins); machine '{getattr(machine, 'name', machine)}' "
            f"is a {type(machine).__name__}"
        )
    L_home = machine.leg_lengths(machine.home_pose)[0]
    home_file = poses_to_file_units(machine.home_pose)
    lines = comment_lines(f"genhexkins configuration for machine '{machine.name}', written by pkmcal {__version__}.")
    lines += [
        "# Units: mm (set [TRAJ] LINEAR_UNITS = mm); A B C in degrees.",
        "# Pose X Y Z A B C = pkmcal x y z a b c: the platform frame in the base (world) frame,",
        "#   R = Rz(C) Ry(B) Rx(A), roll-pitch-yaw about the fixed base axes (pmRpyMatConvert).",
        "# Joint N (N = 0..5) = strut length of pkmcal leg N+1 = |p + R a_N - b_N| (mm),",
        "#   base.N = b_N in the base frame, platform.N = a_N in the platform frame.",
        "# The model has no strut-length correction and no frame shift: genhexkins.screw-lead,",
        "#   genhexkins.spindle-offset and genhexkins.tool-offset must be 0 (their defaults).",
    ]
    if machine.description:
        lines += comment_lines(f"Machine: {machine.description}")
    for n in range(6):
        for axis, k in zip("xyz", range(3)):
            lines.append(f"setp {HAL_PREFIX}.base.{n}.{axis} {_num(machine.base[n, k])}")
    for n in range(6):
        for axis, k in zip("xyz", range(3)):
            lines.append(f"setp {HAL_PREFIX}.platform.{n}.{axis} {_num(machine.platform[n, k])}")
    lines += [
        "#",
        "# Leg offsets and homing. pkmcal's actuator reading is lambda_i = L_i - L0_i; genhexkins'",
        "# joint is the strut length L_i = L0_i + lambda_i. With the home switch at reading",
        "# lambda_i = 0 set [JOINT_N] HOME_OFFSET = L0 below (else L0 + the reading at the switch).",
        "# MIN_LIMIT/MAX_LIMIT = L0 + stroke; HOME = strut length at pkmcal's home pose",
        f"# x y z a b c = {' '.join(_num(v) for v in home_file)} (mm, deg).",
    ]
    for n in range(6):
        lo, hi = machine.offset[n] + machine.stroke[n]
        lines.append(
            f"# pkmcal.joint.{n} leg={n + 1} L0={_num(machine.offset[n])} MIN_LIMIT={_num(lo)} "
            f"MAX_LIMIT={_num(hi)} HOME={_num(L_home[n])}"
        )
    return "\n".join(lines) + "\n"
