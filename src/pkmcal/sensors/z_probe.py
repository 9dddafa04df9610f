"""Z probe: the height of a probe point on the effector above a bed plane (a delta printer's
BLTouch or inductive probe; Klipper's ``PROBE``, ``PROBE_ACCURACY``, ``DELTA_CALIBRATE``).

Model (issue 13, item 3). The platform frame (p, R) is the nozzle (the tool point of the
machine's pose). The probe triggers at a point fixed on the effector, given as Klipper's
``[probe] x_offset, y_offset, z_offset`` = (o_x, o_y, o_z) (params ``probe.x, probe.y,
probe.z``): the probe point sits o_x, o_y beside the nozzle and o_z *below* it, which is
Klipper's sign (z_offset = the nozzle's height above the bed when the probe triggers):

    P = p + R t,        t = (o_x, o_y, −o_z).

The bed is a plane of the base frame through (0, 0, z_b) with normal n = Ry(β) Rx(α) e_z
= (sin β cos α, −sin α, cos β cos α) (params ``bed.z, bed.a, bed.b`` = z_b, α, β; the pose
convention of :mod:`pkmcal.conventions` without its c, mm and radians inside, degrees in
files). The reading is the vertical height of P above the bed (``probe_z``, mm), the
distance the probe still travels straight down before it touches:

    y = n·(P − (0, 0, z_b)) / n_z = P_z − z_b + g_x P_x + g_y P_y,
    g = n / n_z = (tan β, −tan α / cos β, 1).

A probe reads y = 0 at every trigger: the actuator readings at the trigger carry the
information, and the engine's fk-residual fits y − h(FK(q, ρ)) (a feeler gauge under the
nozzle, with a zero probe offset, reads its thickness instead).

Jacobians (analytic; tested against finite differences). With v = R t:

    ∂y/∂p = gᵀ,    ∂y/∂δω = (v × g)ᵀ,    ∂y/∂(o_x, o_y, o_z) = (gᵀR e_x, gᵀR e_y, −gᵀR e_z),
    ∂y/∂z_b = −1,  ∂y/∂α = −P_y sec²α / cos β,  ∂y/∂β = P_x sec²β − P_y tan α sin β / cos²β.

Gauge (what no Z-probe reading can separate). On a machine whose effector does not rotate
(R = I: the deltas), ∂y/∂o_z = −1 = ∂y/∂z_b: the probe's z offset and the bed height are
one combined direction, and so is a common shift of a delta's three endstops (it moves
every z alike); so are o_x, o_y with the tilts at 0 (a level bed does not see where beside
the nozzle the probe is). Klipper's own calibration holds them: the bed is z = 0 and the
probe offsets are measured (``PROBE_CALIBRATE``); hence nothing of this sensor is free
unless named (``free:``), and the identifiability report names the combinations when
they are freed.

Declared: ``measured_frames`` — a probe reads where it triggers, lowered straight down until
y = 0 (a frame moved by (0, 0, −y)); ``readable`` — the probe must approach the bed along
its own axis, so a frame whose z axis R e_z is more than :data:`MAX_PROBE_TILT_DEG` from the
bed normal cannot be read; ``works_with`` — any machine whose platform moves in space (the
default).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors.base import ParamGroup, Sensor

PROBE_PARAM_NAMES = ("probe.x", "probe.y", "probe.z")
BED_PARAM_NAMES = ("bed.z", "bed.a", "bed.b")
_GROUPS = (ParamGroup("probe_offset", PROBE_PARAM_NAMES, (False, False, False)),
           ParamGroup("bed", BED_PARAM_NAMES, (False, True, True)))
#: Largest angle between the probe's axis (the platform z axis) and the bed normal at
#: which the probe is read (degrees): a switch probe must meet the bed about along its axis.
MAX_PROBE_TILT_DEG = 45.0
#: Largest bed tilt a setup file may give (each of bed.a, bed.b, degrees): a bed, not a wall.
MAX_BED_TILT_DEG = 45.0


def _bed(bed: np.ndarray):
    """g = n / n_z (3,) of bed angles α, β, and the bed normal n (3,)."""
    a, b = bed[1], bed[2]
    n = np.array([np.sin(b) * np.cos(a), -np.sin(a), np.cos(b) * np.cos(a)])
    return n / n[2], n


@dataclass(frozen=True, eq=False)
class ZProbeSensor(Sensor):
    """A Z probe on the effector reading its height above a bed plane (module docstring).

    Parameters
    ----------
    probe_offset : (3,) Klipper's ``x_offset, y_offset, z_offset`` (mm): the probe point is
        at (x, y, −z) from the nozzle in the platform frame; default 0 (the nozzle itself).
    bed : (3,) bed height z_b (mm) and tilts α, β (rad, about the base x and y axes);
        default 0 (the plane z = 0).
    free : sensor parameters estimated by the identification (default: none).
    """

    probe_offset: np.ndarray = None  # type: ignore[assignment]
    bed: np.ndarray = None  # type: ignore[assignment]
    free: tuple[str, ...] | None = None

    kind = "z-probe"
    #: it reads where it triggers when lowered (:meth:`measured_frames`): a study can put its
    #: probe points on the bed (a study setup's ``on_bed``, :mod:`pkmcal.study.printed`)
    abilities = frozenset({"touch-probe"})
    #: heights only: a common scale of the machine changes them by a hair (a delta's arms
    #: and radius together: σ 1.5 % from 37 points, `pkmcal identifiability`)
    sees_length = False
    reads_one_plane = True

    def __post_init__(self) -> None:
        self._init_params()

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return _GROUPS

    @property
    def reading_names(self) -> tuple[str, ...]:
        return ("probe_z",)

    def _parts(self, params):
        """(t (3,) the probe point in the platform frame, bed (3,)) at θ = ``params``."""
        theta = self._theta(params)
        off, bed = (self.probe_offset, self.bed) if theta is None else (theta[0:3], theta[3:6])
        return np.array([off[0], off[1], -off[2]]), bed

    @staticmethod
    def _point(frame: Frame, t: np.ndarray):
        """v = R t (N, 3) and P = p + v (N, 3)."""
        v = frame.R @ t
        return v, frame.p + v

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings (N, 1): the probe point's height above the bed, mm."""
        t, bed = self._parts(params)
        g, _ = _bed(bed)
        _, P = self._point(frame, t)
        return (P @ g - bed[0])[:, None]

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(δp, δω) (N, 1, 6): (gᵀ, (R t × g)ᵀ)."""
        t, bed = self._parts(params)
        g, _ = _bed(bed)
        v, _ = self._point(frame, t)
        J = np.empty((len(frame), 1, 6))
        J[:, 0, 0:3] = g
        J[:, 0, 3:6] = np.cross(v, g)
        return J

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂θ (N, 1, 6), θ = probe.x, probe.y, probe.z, bed.z, bed.a, bed.b (module docstring)."""
        t, bed = self._parts(params)
        g, _ = _bed(bed)
        _, P = self._point(frame, t)
        a, b = bed[1], bed[2]
        J = np.empty((len(frame), 1, 6))
        gR = g @ frame.R                                           # gᵀR (N, 3)
        J[:, 0, 0:2] = gR[:, 0:2]
        J[:, 0, 2] = -gR[:, 2]
        J[:, 0, 3] = -1.0
        J[:, 0, 4] = -P[:, 1] / (np.cos(a) ** 2 * np.cos(b))
        J[:, 0, 5] = P[:, 0] / np.cos(b) ** 2 - P[:, 1] * np.tan(a) * np.sin(b) / np.cos(b) ** 2
        return J

    def probe_points(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """P = p + R t (N, 3): where the probe point is with the platform at ``frame`` (mm)."""
        t, _ = self._parts(params)
        return self._point(frame, t)[1]

    def measured_frames(self, frame: Frame) -> Frame:
        """Where the probe triggers when lowered straight down from ``frame``: y falls 1:1
        with the frame's height (∂y/∂p_z = g_z = 1), so the frame moved by (0, 0, −y(frame))
        reads 0: the probe point on the bed."""
        y = self.predict(frame)[:, 0]
        return Frame(p=frame.p - y[:, None] * np.array([0.0, 0.0, 1.0]), R=frame.R)

    def readable(self, frame: Frame) -> tuple[np.ndarray, str]:
        """Frames whose probe axis (R e_z) is within :data:`MAX_PROBE_TILT_DEG` of the bed
        normal (all frames of a delta, whose effector stays level)."""
        _, n = _bed(self.bed)
        return frame.z_axis @ n >= np.cos(np.deg2rad(MAX_PROBE_TILT_DEG)), "probe axis too far from the bed normal"
