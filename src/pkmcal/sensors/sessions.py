"""Several measurement sessions in one fit: one copy of the sensor's parameters per session.

A campaign measured in sessions (the motion-capture system set up again, the dial
indicators re-zeroed, the tracker moved) shares the machine but not the sensor: each
session s has its own sensor parameters θ_s (world/tool frames, indicator zeros, plate),

    y_j = h(F_j, θ_{s(j)}),        θ = [θ_1; θ_2; …; θ_S]                            (1)

with s(j) the session of pose j (the ``session`` column of the measurement file, labels
in order of first appearance). The parameters of session s are named ``NAME@LABEL``
(``world.x@2``). Optionally each session but the first has actuator zero offsets δq_s
(re-homing: ``dq_i@LABEL``), the readings of session s then being those of a machine
whose zeros moved by δq_s, IK(x_j, ρ) = q_j + δq_{s(j)}; the first session's zeros are the
machine's own (the gauge). The engine (:mod:`pkmcal.identification.residuals`) applies
that shift and its Jacobian columns; this module holds the sessions and the sensor (1).

:class:`Sessions` is the session of every pose (labels, index per pose, the poses of each
session as a slice when contiguous, else an index array). :class:`SessionSensor` is a
:class:`~pkmcal.sensors.base.Sensor` with θ the stacked per-session θ_s, bound to the
poses of one :class:`Sessions`: it evaluates each session's sensor on that session's
frames, one call per session (never a loop over poses), and its parameter Jacobian is
block diagonal, ∂y_j/∂θ_s = ∂h/∂θ (F_j, θ_s) for s = s(j), zero otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.mechanisms.frame import Frame
from pkmcal.sensors.base import ParamGroup, Sensor

#: Separator between a sensor parameter's name and its session label.
SESSION_SEPARATOR = "@"


def session_name(name: str, label: str) -> str:
    """``NAME@LABEL``: the name of parameter ``name`` in session ``label``."""
    return f"{name}{SESSION_SEPARATOR}{label}"


def offset_names(actuator_count: int, labels: tuple[str, ...]) -> tuple[str, ...]:
    """Names of the re-homing offsets: ``dq_1@L … dq_l@L`` for every session L but the first."""
    return tuple(session_name(f"dq_{i + 1}", lab) for lab in labels[1:] for i in range(actuator_count))


@dataclass(frozen=True, eq=False)
class Sessions:
    """The session of each of N poses: ``labels`` (S,) in order of first appearance,
    ``index`` (N,) the position of each pose's label in ``labels``, and ``offsets``:
    whether the sessions after the first have actuator zero offsets (re-homing)."""

    labels: tuple[str, ...]
    index: np.ndarray
    offsets: bool = False
    _groups: list = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        idx = np.asarray(self.index, dtype=np.intp).reshape(-1)
        if len(idx) and (idx.min() < 0 or idx.max() >= len(self.labels)):
            raise PkmcalError(f"session index out of range for {len(self.labels)} session(s)")
        idx.setflags(write=False)
        object.__setattr__(self, "index", idx)
        object.__setattr__(self, "labels", tuple(str(lab) for lab in self.labels))

    @classmethod
    def from_labels(cls, per_pose, offsets: bool = False) -> Sessions:
        """The sessions of per-pose labels (N,), labels in order of first appearance."""
        per_pose = [str(v) for v in per_pose]
        labels: dict[str, int] = {}
        index = np.array([labels.setdefault(v, len(labels)) for v in per_pose], dtype=np.intp)
        return cls(tuple(labels), index, offsets)

    @classmethod
    def single(cls, n: int) -> Sessions:
        """One session holding all n poses (names as without sessions)."""
        return cls(("1",), np.zeros(n, dtype=np.intp))

    def __len__(self) -> int:
        return len(self.index)

    @property
    def n_sessions(self) -> int:
        return len(self.labels)

    @property
    def several(self) -> bool:
        """True with more than one session: parameters named ``NAME@LABEL``."""
        return len(self.labels) > 1

    @property
    def groups(self) -> list:
        """The poses of each session (S entries): a slice when contiguous, else indices."""
        if self._groups is None:
            out = []
            for k in range(len(self.labels)):
                idx = np.flatnonzero(self.index == k)
                if len(idx) and idx[-1] - idx[0] + 1 == len(idx):
                    out.append(slice(int(idx[0]), int(idx[-1]) + 1))
                else:
                    out.append(idx)
            object.__setattr__(self, "_groups", out)
        return self._groups

    def counts(self) -> np.ndarray:
        """Poses per session (S,)."""
        return np.bincount(self.index, minlength=len(self.labels))

    def subset(self, keep) -> Sessions:
        """The sessions of the poses ``keep`` (mask or indices); the labels stay (a session
        whose poses were all left out keeps its parameters, which the data then do not see)."""
        return Sessions(self.labels, self.index[keep], self.offsets)

    def with_offsets(self, offsets: bool) -> Sessions:
        return Sessions(self.labels, self.index, bool(offsets))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Sessions):
            return NotImplemented
        return (self.labels == other.labels and self.offsets == other.offsets
                and np.array_equal(self.index, other.index))

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True, eq=False)
class SessionSensor(Sensor):
    """Sensor (1) of the module docstring: ``sensors[s]`` the sensor of session s (same kind
    and geometry, its own θ_s and ``free``), bound to the poses of ``sessions``."""

    sensors: tuple[Sensor, ...]
    sessions: Sessions

    def __post_init__(self) -> None:
        sensors = tuple(self.sensors)
        if len(sensors) != self.sessions.n_sessions:
            raise PkmcalError(f"{len(sensors)} sensors for {self.sessions.n_sessions} sessions")
        first = sensors[0]
        if any(type(s) is not type(first) or s.param_names != first.param_names for s in sensors[1:]):
            raise PkmcalError("the sensors of a multi-session fit must all be of one kind and geometry")
        object.__setattr__(self, "sensors", sensors)

    @classmethod
    def start(cls, sensor: Sensor, sessions: Sessions, values: dict | None = None) -> SessionSensor:
        """Every session starting from ``sensor`` (θ, free), or from ``values[label]`` (a
        sensor) for the labels given there (e.g. the identified sessions of a calibrated file)."""
        values = values or {}
        for lab, s in values.items():
            if type(s) is not type(sensor) or s.param_names != sensor.param_names:
                raise PkmcalError(f"the sensor given for session '{lab}' is not of the setup's kind and geometry")
        return cls(tuple(values.get(lab, sensor) for lab in sessions.labels), sessions)

    def bound(self, sessions: Sessions) -> SessionSensor:
        """The same sensors bound to other poses (same labels: a subset, or new data)."""
        if sessions.labels != self.sessions.labels:
            raise PkmcalError(f"sessions {', '.join(sessions.labels)} differ from the sensor's "
                              f"{', '.join(self.sessions.labels)}")
        return SessionSensor(self.sensors, sessions)

    def session(self, label: str) -> Sensor:
        """The sensor of session ``label``, with its own θ."""
        try:
            return self.sensors[self.sessions.labels.index(str(label))]
        except ValueError:
            raise PkmcalError(f"no session '{label}'; the sessions are {', '.join(self.sessions.labels)}") from None

    # -- the Sensor interface --------------------------------------------------------------

    @property
    def kind(self) -> str:  # type: ignore[override]
        return self.sensors[0].kind

    @property
    def free(self) -> tuple[str, ...]:  # type: ignore[override]
        return self.default_free

    @property
    def invertible(self) -> bool:  # type: ignore[override]
        return self.sensors[0].invertible

    @property
    def abilities(self) -> frozenset[str]:  # type: ignore[override]
        return frozenset()     # per-session geometry: no single tool point to offer

    @property
    def sees_length(self) -> bool:  # type: ignore[override]
        return any(s.sees_length for s in self.sensors)

    @property
    def reads_one_plane(self) -> bool:  # type: ignore[override]
        return all(s.reads_one_plane for s in self.sensors)

    @property
    def reading_names(self) -> tuple[str, ...]:
        return self.sensors[0].reading_names

    @property
    def reading_is_angle(self) -> tuple[bool, ...]:
        return self.sensors[0].reading_is_angle

    @property
    def param_groups(self) -> tuple[ParamGroup, ...]:
        return ()    # θ is the stacked per-session θ_s: names and values below

    @cached_property
    def param_names(self) -> tuple[str, ...]:
        return tuple(session_name(n, lab) for lab, s in zip(self.sessions.labels, self.sensors)
                     for n in s.param_names)

    @cached_property
    def param_is_angle(self) -> tuple[bool, ...]:
        return tuple(a for s in self.sensors for a in s.param_is_angle)

    @property
    def params(self) -> np.ndarray:
        return np.concatenate([s.params for s in self.sensors])

    @property
    def default_free(self) -> tuple[str, ...]:
        return tuple(session_name(n, lab) for lab, s in zip(self.sessions.labels, self.sensors)
                     for n in s.default_free)

    def with_params(self, params: np.ndarray) -> SessionSensor:
        thetas = self._split(params, check=True)
        return SessionSensor(tuple(s.with_params(t.copy()) for s, t in zip(self.sensors, thetas)), self.sessions)

    def _split(self, params, check: bool = False) -> list:
        """θ_s of each session (views), the sensors' own for ``params=None``."""
        if params is None:
            return [s.params for s in self.sensors]
        theta = np.asarray(params, dtype=float).reshape(-1)
        n = len(self.sensors[0].param_names)
        if theta.shape != (n * len(self.sensors),):
            raise PkmcalError(f"{self.kind} sensor of {len(self.sensors)} sessions has {n * len(self.sensors)} "
                              f"parameters; got {theta.size} values")
        if check and not np.all(np.isfinite(theta)):
            bad = self.param_names[int(np.argmax(~np.isfinite(theta)))]
            raise PkmcalError(f"{self.kind} sensor parameter '{bad}' is not a finite number")
        return [theta[k * n:(k + 1) * n] for k in range(len(self.sensors))]

    def _check(self, n: int) -> None:
        if n != len(self.sessions):
            raise PkmcalError(f"the {self.kind} sensor of {self.sessions.n_sessions} sessions is bound to "
                              f"{len(self.sessions)} poses; got {n}")

    def _each(self, frame: Frame, params, call, width) -> np.ndarray:
        """``call(sensor_s, frames of s, θ_s)`` (n_s, m, *width) of every session, in pose order."""
        self._check(len(frame))
        out = np.empty((len(frame), self.n_readings) + width)
        for s, g, th in zip(self.sensors, self.sessions.groups, self._split(params)):
            out[g] = call(s, frame[g], th)
        return out

    def predict(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        return self._each(frame, params, lambda s, f, th: s.predict(f, th), ())

    def frame_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        return self._each(frame, params, lambda s, f, th: s.frame_jacobian(f, th), (6,))

    def param_jacobian(self, frame: Frame, params: np.ndarray | None = None) -> np.ndarray:
        """Block diagonal ∂y/∂θ (N, m, S·s) (module docstring)."""
        self._check(len(frame))
        n = len(self.sensors[0].param_names)
        out = np.zeros((len(frame), self.n_readings, n * len(self.sensors)))
        for k, (s, g, th) in enumerate(zip(self.sensors, self.sessions.groups, self._split(params))):
            out[g, :, k * n:(k + 1) * n] = s.param_jacobian(frame[g], th)
        return out

    def readable(self, frame: Frame) -> tuple[np.ndarray, str]:
        self._check(len(frame))
        ok = np.ones(len(frame), dtype=bool)
        reasons = []
        for s, g in zip(self.sensors, self.sessions.groups):
            ok[g], why = s.readable(frame[g])
            if why and why not in reasons:
                reasons.append(why)
        return ok, "; ".join(reasons)

    def works_with(self, mechanism) -> str | None:
        return self.sensors[0].works_with(mechanism)

    def reads_pose(self, params: np.ndarray | None = None) -> bool:
        return all(s.reads_pose(th) for s, th in zip(self.sensors, self._split(params)))

    def invert(self, readings: np.ndarray, params: np.ndarray | None = None) -> Frame:
        readings = np.asarray(readings, dtype=float)
        self._check(len(readings))
        p, R = np.empty((len(readings), 3)), np.empty((len(readings), 3, 3))
        for s, g, th in zip(self.sensors, self.sessions.groups, self._split(params)):
            f = s.invert(readings[g], th)
            p[g], R[g] = f.p, f.R
        return Frame(p=p, R=R)

    def reading_residual(self, measured: np.ndarray, predicted: np.ndarray) -> np.ndarray:
        return self.sensors[0].reading_residual(measured, predicted)

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, SessionSensor):
            return NotImplemented
        return self.sessions == other.sessions and self.sensors == other.sensors

    __hash__ = None  # type: ignore[assignment]


def setup_values(sensor: Sensor, angle=None) -> dict:
    """The sensor's θ in setup-file form: each θ field (``world``, ``tool``, ``target``,
    ``plate``) a mapping of the names after the dot (``world.c`` → ``c``), a field of plain
    names (``zero1 … zeroK``) a list; mm, and angles through ``angle(radians)`` (default
    degrees as a float; a YAML writer passes its exact degree text)."""
    angle = angle or (lambda v: float(np.rad2deg(v)))
    out: dict = {}
    for g in sensor.param_groups:
        values = [angle(v) if a else float(v) for v, a in zip(getattr(sensor, g.field), g.is_angle)]
        if all("." in n for n in g.names):
            out[g.field] = {n.split(".", 1)[1]: v for n, v in zip(g.names, values)}
        else:
            out[g.field] = values
    return out


def sensor_from_values(sensor: Sensor, values: dict, angle=None) -> Sensor:
    """``sensor`` with the θ fields that ``values`` gives (setup-file form, the reverse of
    :func:`setup_values`; file units, angles through ``angle(degrees)``, default
    ``np.deg2rad``): a transform's coordinates not given are 0, as in setup files; a field
    not given keeps ``sensor``'s values. ``dq`` (re-homing offsets) is not a sensor field and
    is skipped. Raises :class:`PkmcalError` naming the key for an unknown key or a value that
    is not a finite number."""
    angle = angle or (lambda v: float(np.deg2rad(v)))
    fields_ = {g.field: g for g in sensor.param_groups}
    unknown = [k for k in values if k not in fields_ and k != "dq"]
    if unknown:
        raise PkmcalError(f"'{unknown[0]}' is not a parameter group of the '{sensor.kind}' sensor "
                          f"(its groups: {', '.join(fields_) or 'none'})")

    def number(v, key: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(float(v)):
            raise PkmcalError(f"'{key}' must be a finite number; got {v!r}")
        return v

    theta = []
    for g in sensor.param_groups:
        given = values.get(g.field)
        if given is None:
            theta.extend(getattr(sensor, g.field))
            continue
        if all("." in n for n in g.names):
            keys = [n.split(".", 1)[1] for n in g.names]
            if not isinstance(given, dict) or any(k not in keys for k in given):
                bad = next((k for k in given if k not in keys), None) if isinstance(given, dict) else None
                raise PkmcalError(f"'{g.field}' is a mapping of {', '.join(keys)}" +
                                  (f"; '{bad}' is not one of them" if bad is not None else ""))
            raw = [number(given.get(k, 0.0), f"{g.field}.{k}") for k in keys]
        else:
            if not isinstance(given, list) or len(given) != len(g.names):
                raise PkmcalError(f"'{g.field}' is a list of {len(g.names)} numbers")
            raw = [number(v, f"{g.field}[{i}]") for i, v in enumerate(given)]
        theta.extend(angle(v) if a else float(v) for v, a in zip(raw, g.is_angle))
    return sensor.with_params(np.array(theta, dtype=float))


def session_setup_values(sensor: Sensor, offsets: dict | None = None, actuator_is_angle=(), angle=None) -> dict:
    """{label: setup-file keys} of every session of a :class:`SessionSensor`
    (:func:`setup_values`), with ``dq`` the session's re-homing offsets (``offsets[label]``,
    internal units; mm, angles for the rotary actuators of ``actuator_is_angle``) where
    given; empty for a one-session sensor. The calibrated file's ``setup: sessions:``."""
    if not isinstance(sensor, SessionSensor):
        return {}
    angle = angle or (lambda v: float(np.rad2deg(v)))
    out = {}
    for lab, s in zip(sensor.sessions.labels, sensor.sensors):
        out[lab] = setup_values(s, angle)
        if offsets and lab in offsets:
            flags = tuple(actuator_is_angle) or (False,) * len(offsets[lab])
            out[lab]["dq"] = [angle(v) if a else float(v) for v, a in zip(offsets[lab], flags)]
    return out


def bind_sessions(sensor: Sensor, sessions: Sessions | None) -> Sensor:
    """The sensor of the poses of ``sessions``: with several sessions a
    :class:`SessionSensor` bound to them (``sensor`` itself when it is one, rebound; every
    session starting from ``sensor`` when it is a plain sensor); with one session or None
    the plain ``sensor`` (names as without sessions)."""
    several = sessions is not None and sessions.several
    if isinstance(sensor, SessionSensor):
        if not several:
            raise PkmcalError("a sensor of several sessions needs the session of every pose")
        return sensor.bound(sessions)
    return SessionSensor.start(sensor, sessions) if several else sensor


def session_sensors(sensor: Sensor) -> dict[str, Sensor]:
    """{label: sensor of that session}: one entry ``{"": sensor}`` for a one-session sensor."""
    if isinstance(sensor, SessionSensor):
        return dict(zip(sensor.sessions.labels, sensor.sensors))
    return {"": sensor}


__all__ = ["SESSION_SEPARATOR", "SessionSensor", "Sessions", "bind_sessions", "offset_names", "session_name", "session_sensors",
           "sensor_from_values", "session_setup_values", "setup_values"]
