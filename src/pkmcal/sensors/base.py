"""The sensor interface: what an external measuring device reads of the platform frame.

A sensor model is ``y = h(F, θ)``: the readings y (m,) it gives when the platform frame is
F = (p, R) in the base frame (:class:`~pkmcal.mechanisms.frame.Frame`; mm, rotation
matrices), with θ the sensor's own parameters (e.g. an unknown world→base transform, a
target offset on the platform, indicator zero offsets). A sensor never sees a machine's
pose coordinates, so it works with any mechanism whose frame it can read. Every sensor
supplies analytic derivatives with respect to the frame's twist (δp, δω) (δω a base-frame
rotation vector, :mod:`pkmcal.mechanisms.frame`), ``frame_jacobian`` (N, m, 6), and with
respect to θ, ``param_jacobian`` (N, m, s); the engine composes the pose Jacobian
∂y/∂x = frame_jacobian · T with the mechanism's T = ∂twist/∂x. Parameters θ may be given
explicitly (``params=``; default the sensor's own), as the engine does.

Declared, not probed: ``readable(frame)`` says which frames the sensor can read and why
not; ``works_with(mechanism)`` whether it can measure a machine at all; ``invertible``
whether the readings determine the frame (``invert``: the full-pose sensor of paper 1);
``abilities`` optional features (``"touch-probe"``: reads where it triggers when lowered,
:meth:`Sensor.measured_frames`, its probe point ``probe_points(frame)`` and its bed plane
``bed`` (z_b, α, β); ``"tool-point"``: a planar tool point with
``tool_point``/``tool_frame_jacobian``).

The actuators are the machine's own sensor: their readings are ``q = IK(x, ρ)``, with the
noise given by :class:`NoiseModel`. A :class:`MeasurementSetup` bundles a sensor with the
noise of its readings and of the actuators; it is what a setup YAML file describes.

Concrete sensors are frozen dataclasses that hold θ in the fields listed by
:attr:`Sensor.param_groups` (θ = their concatenation, each group with its parameter names
and which of them are angles). From that one declaration the base class derives
``param_names``, ``param_is_angle``, ``params``, ``with_params`` and value equality (same
kind and equal fields: geometry, θ and the free names), so no sensor repeats them.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, fields, replace
from functools import cached_property
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from pkmcal.sensors._common import check_free, check_params

if TYPE_CHECKING:
    from pkmcal.mechanisms.base import Mechanism
    from pkmcal.mechanisms.frame import Frame
    from pkmcal.mechanisms.statics import StaticsModel


class ParamGroup(NamedTuple):
    """One field of a sensor dataclass holding part of θ: the field's name, the names of the
    parameters it holds and which of them are angles (radians inside, degrees in files)."""

    field: str
    names: tuple[str, ...]
    is_angle: tuple[bool, ...]


class Sensor(ABC):
    """Abstract external sensor (see module docstring). A concrete sensor is a frozen
    dataclass (``eq=False``: equality is :meth:`__eq__` here) with a ``free`` field and the
    θ fields of :attr:`param_groups`, and calls :meth:`_init_params` in ``__post_init__``."""

    #: Sensor kind as written in setup files: "full-pose", "position", "indicators", ...
    kind: str
    #: Names of the parameters estimated by default; None: :attr:`free_when_unset`.
    free: tuple[str, ...] | None
    #: :attr:`default_free` of a sensor whose ``free`` is None.
    free_when_unset: tuple[str, ...] = ()
    #: True when the readings determine the platform frame (:meth:`invert`).
    invertible: bool = False
    #: Optional features, asked as ``"x" in sensor.abilities`` (module docstring).
    abilities: frozenset[str] = frozenset()
    #: True when a reading couples two poses: the machine is then read as pose pairs
    #: (:mod:`pkmcal.mechanisms.pose_pairs`; :func:`~pkmcal.mechanisms.pose_pairs.read_by`).
    reads_pose_pairs: bool = False
    #: False when the readings determine no length of the machine, only heights above a
    #: plane (a Z probe): a fit then holds by default what such readings leave to within
    #: more than a print's tolerance (the mechanism's ``held_without_length``).
    sees_length: bool = True
    #: True when every reading is taken on one plane (a bed: a Z probe, a printed first
    #: layer): what only shows across heights (a delta's rail leans) is then held by default
    #: (the mechanism's ``held_on_one_plane``).
    reads_one_plane: bool = False

    @property
    @abstractmethod
    def reading_names(self) -> tuple[str, ...]:
        """CSV column names of the readings, e.g. ("x", ..., "c") or ("d1", "d2", "d3")."""

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        """True for readings that are angles (degrees in files, radians inside)."""
        return (False,) * len(self.reading_names)

    @property
    def n_readings(self) -> int:
        return len(self.reading_names)

    @property
    @abstractmethod
    def param_groups(self) -> tuple[ParamGroup, ...]:
        """The dataclass fields holding θ, in the order of θ (may be empty)."""

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        """Names of the sensor's own parameters θ (may be empty; computed once per sensor)."""
        return tuple(n for g in self.param_groups for n in g.names)

    @cached_property
    def param_is_angle(self) -> tuple[bool, ...]:
        """True for the parameters of :attr:`param_names` that are angles (radians inside,
        degrees in files and tables); same meaning as the mechanisms' ``param_is_angle``."""
        return tuple(a for g in self.param_groups for a in g.is_angle)

    @property
    def params(self) -> np.ndarray:
        """Current values of θ (s,), internal units (a fresh, writable array)."""
        groups = self.param_groups
        if not groups:
            return np.zeros(0)
        return np.concatenate([getattr(self, g.field) for g in groups])

    @property
    def default_free(self) -> tuple[str, ...]:
        """Sensor parameters estimated by default (the rest are held at their values)."""
        return self.free_when_unset if self.free is None else self.free

    def with_params(self, params: np.ndarray) -> Sensor:
        """A copy of this sensor with θ replaced."""
        theta = check_params(params, self.param_names, self.kind)
        parts, i = {}, 0
        for g in self.param_groups:
            parts[g.field] = theta[i:i + len(g.names)]
            i += len(g.names)
        return replace(self, **parts)

    def _init_params(self) -> None:
        """For ``__post_init__``: each θ field as a read-only float array of its length
        (None → zeros) and ``free`` checked against :attr:`param_names`."""
        for g in self.param_groups:
            value = getattr(self, g.field)
            value = np.zeros(len(g.names)) if value is None else value
            object.__setattr__(self, g.field, check_params(value, g.names, self.kind))
        object.__setattr__(self, "free", check_free(self.free, self.param_names, self.kind))

    def __eq__(self, other: object) -> bool:
        """Value equality: the same kind (class) and equal dataclass fields (geometry, θ, free)."""
        if not isinstance(other, Sensor):
            return NotImplemented
        if type(self) is not type(other):
            return False
        return all(_same(getattr(self, f.name), getattr(other, f.name)) for f in fields(self))

    __hash__ = None  # type: ignore[assignment]  # equal by array values: not hashable

    def _theta(self, params) -> np.ndarray | None:
        """θ as a float vector (s,), or None for ``params=None`` (the sensor's own)."""
        if params is None:
            return None
        theta = np.asarray(params, dtype=float)
        if theta.shape != (len(self.param_names),):
            check_params(theta, self.param_names, self.kind)   # raises with the names
        return theta

    @abstractmethod
    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Readings y (N, m) of the platform frames, at θ = ``params`` (default own)."""

    @abstractmethod
    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂(δp, δω) (N, m, 6): the readings' derivative with respect to the frame's twist."""

    @abstractmethod
    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """∂y/∂θ (N, m, s)."""

    def readable(self, frame: Frame) -> tuple[np.ndarray, str]:
        """``(ok, reason)``: ok (N,) True where the sensor can read the frame; ``reason``
        why the others cannot (a short phrase). Default: every frame."""
        return np.ones(len(frame), dtype=bool), ""

    def works_with(self, mechanism: Mechanism) -> str | None:
        """None when this sensor can measure ``mechanism``, else why not (a sentence).

        Default (the spatial sensors): any machine whose platform frame moves in space, not a
        planar machine (``"planar"`` in its abilities), whose frame keeps z, roll and pitch
        fixed: their readings would carry rows that nothing moves; a planar machine is
        measured by the planar-tool sensor."""
        if "planar" in mechanism.abilities:
            return (f"a '{self.kind}' sensor cannot measure machine '{mechanism.name}' ({mechanism.n_dof} pose "
                    "coordinates, a planar machine); use a 'planar-tool' setup")
        return None

    def measured_readings(self, frame: Frame) -> np.ndarray:
        """Which readings of each frame are measurements (N, m) bool: all (default). A reading
        that is not (a row of two poses that measures one of its two readings and records the
        other as 0, predicted 0: :class:`~pkmcal.sensors.printed_distance.PrintedDistanceSensor`)
        adds no degree of freedom to a fit's χ² (:mod:`pkmcal.identification.uncertainty`)."""
        return np.ones((len(frame), self.n_readings), dtype=bool)

    def measured_frames(self, frame: Frame) -> Frame:
        """The frames at which this sensor takes its readings when the machine is sent to
        ``frame``: the frames themselves (default); a touch probe's are lowered until it
        triggers (:class:`~pkmcal.sensors.z_probe.ZProbeSensor`). What a plan of more poses
        for this sensor measures (:mod:`pkmcal.identification.advice`)."""
        return frame

    def reads_pose(self, params: np.ndarray | None = None) -> bool:
        """True when, at θ = ``params``, the readings are exactly the frame's x, y, z, a, b, c
        in the pose convention of :mod:`pkmcal.conventions` (no transform): on a mechanism
        with the ``"pose-convention"`` ability they are then the pose itself (∂y/∂x = I), which
        the ik-residual uses as such, bit for bit. Default False."""
        return False

    def invert(self, readings: np.ndarray, params: np.ndarray | None = None) -> Frame:
        """The platform frames whose readings are ``readings`` (N, m); only for
        :attr:`invertible` sensors."""
        from pkmcal.errors import PkmcalError

        raise PkmcalError(f"the '{self.kind}' sensor's readings do not determine the platform frame")

    def reading_residual(self, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        """``measured − predicted`` (N, m); sensors with angle readings wrap them to (−π, π]."""
        r = np.asarray(measured, dtype=float) - predicted
        ang = np.array(self.reading_is_angle, dtype=bool)
        if ang.any():
            r[..., ang] = (r[..., ang] + np.pi) % (2 * np.pi) - np.pi
        return r


def _same(a, b) -> bool:
    """Field equality for :meth:`Sensor.__eq__`: arrays by shape and values, else ``==``."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return bool(np.array_equal(a, b))
    return bool(a == b)


@dataclass(frozen=True)
class NoiseModel:
    """Measurement noise. ``reading_std`` (m,) for the sensor readings and ``actuator_std``
    (l,) for the actuator readings, as standard deviations in internal units (mm, rad).

    ``distribution`` is "gaussian" or "uniform"; a uniform noise of half-width h has the
    standard deviation h/√3, which is what is stored here (the setup file may give
    half-widths; the loader converts).
    """

    reading_std: np.ndarray
    actuator_std: np.ndarray
    distribution: str = "gaussian"

    def sample(self, rng: np.random.Generator, shape_readings, shape_actuators):
        """Seeded noise draws ``(e_y, e_q)`` of the given shapes (N, m) and (N, l)."""
        def draw(std, shape):
            std = np.broadcast_to(np.asarray(std, dtype=float), shape[-1:])
            if self.distribution == "uniform":
                h = std * np.sqrt(3.0)
                return rng.uniform(-1.0, 1.0, size=shape) * h
            return rng.standard_normal(size=shape) * std
        return draw(self.reading_std, shape_readings), draw(self.actuator_std, shape_actuators)


@dataclass(frozen=True)
class MeasurementSetup:
    """A sensor and the noise of its readings and of the actuators; optionally the physics
    that only a simulation uses (``simulation``: a
    :class:`~pkmcal.mechanisms.statics.StaticsModel`, actuator stiffness and tool load of a
    redundantly actuated machine; the identifier never reads it); ``priors``: Gaussian
    priors on parameters (:class:`~pkmcal.identification.priors.Prior`, the setup file's
    ``prior:``), which the identification adds to its own; ``session_offsets`` and
    ``session_sensors`` the setup's ``sessions:`` (several measurement sessions)."""

    sensor: Sensor
    noise: NoiseModel
    simulation: StaticsModel | None = None
    priors: tuple = ()
    #: the setup's ``sessions: {actuator_offsets: true}``: with several sessions in the
    #: measurements, the sessions after the first get actuator zero offsets (re-homing;
    #: :mod:`pkmcal.sensors.sessions`)
    session_offsets: bool = False
    #: ((label, sensor), ...): the sensors of named sessions (a calibrated file's
    #: ``sessions:``), the starting values of those sessions in a multi-session fit
    session_sensors: tuple = ()
