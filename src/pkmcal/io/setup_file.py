"""Measurement setup files (YAML): which sensor, where it is, and how noisy everything is.

A setup file describes a :class:`~pkmcal.sensors.base.MeasurementSetup`. Lengths in mm,
angles of transforms in degrees; noise values are standard deviations, or half-widths
with ``distribution: uniform`` (converted to std = h/√3, the std of U(−h, h)).

Dial indicators (paper 2 §2.3, eqs. 4–6)::

    sensor: indicators
    indicators: [[40, 0], [-20, 34.641], [-20, -34.641]]   # x, y in the base frame, mm
    plane_offset: 10.0            # platform origin above its lower plane, mm
    zero: [0, 0, 0]               # optional indicator zero offsets, mm
    plate: {x: 0, y: 0, z: 0, a: 0, b: 0, c: 0}   # optional: pose of the indicator plate in the base, mm/deg
    free: [zero1, zero2, zero3]   # optional: sensor parameters to estimate (also plate.x ... plate.c)
    noise: {reading: 0.01, actuator: 0.005}               # std, mm

Full pose (paper 1 §III), with optional world→base and platform→target transforms::

    sensor: full-pose
    world: {x: 0, y: 0, z: 0, a: 0, b: 0, c: 0}    # pose of the base in the sensor frame, mm/deg
    tool: {x: 0, y: 0, z: 25}                      # target frame on the platform, mm/deg
    noise: {distribution: uniform, position: 0.025, orientation_deg: 0.0573, actuator: 0.01}

``orientation_deg`` is in degrees, as every angle in files (docs/conventions.md); the older
key ``orientation`` is still read, in radians as it always was; ``reading``, ``position``,
``orientation_deg`` and ``actuator`` take one value or one per reading/actuator. A 3D tracker::

    sensor: position
    target: {x: 0, y: 0, z: 30}   # initial target offset on the platform, mm (free by default)
    noise: {reading: 0.01, actuator: 0.005}

A tracker on the tool point of a planar machine (paper 3 §3), with the physics that only
``pkmcal simulate`` / ``pkmcal verify`` use (the identifier never sees them)::

    sensor: planar-tool
    target: {x: 0, y: 0}          # tool point P_t in the plate frame, mm (free by default)
    world: {x: 0, y: 0, c: 0}     # optional: base frame in the tracker frame, mm / deg
    free: [target.x, target.y, world.x, world.y, world.c]   # optional: unknown tracker frame
    noise: {reading: 0.010, actuator: 1.0e-5}    # tracker mm; encoders mm (linear) or rad (rotary)
    simulation:
      stiffness: 5.0e7            # actuator stiffness K: N/mm (linear) or N·mm/rad (rotary); one or one per actuator
      load: [0, -30]              # in-plane force on the tool point, N (base frame)
      backlash: 1.0e-4            # optional dead band per actuator, mm (linear) or rad (rotary); one or one per actuator

A delta printer's Z probe (Klipper's ``[probe]``/``[bltouch]`` offsets; the bed a plane of
the base frame), :mod:`pkmcal.sensors.z_probe`::

    sensor: z-probe
    probe_offset: [0.0, 0.0, 1.25]    # Klipper's x_offset, y_offset, z_offset, mm (optional, default 0)
    bed: {z: 0, a: 0, b: 0}           # optional: bed height (mm) and tilts about x and y (deg)
    free: [bed.a, bed.b]              # optional (default none): also probe.x/y/z, bed.z
    noise: {reading: 0.005, actuator: 0.0036}   # probe trigger std, carriage std (mm)

Printed-object distances with the probe heights (Klipper's ``DELTA_ANALYZE``; the machine
read as pose pairs), :mod:`pkmcal.sensors.printed_distance`: the z-probe's keys, and two
reading noises::

    sensor: printed-distance
    probe_offset: [0.0, 0.0, 1.25]
    noise: {reading: [0.005, 0.02], actuator: 0.0036}   # probe std, calipers std, carriage std (mm)

Any setup may give Gaussian priors on parameters (maximum a posteriori identification,
:mod:`pkmcal.identification.priors`): names or shell patterns, each ``[mean, std]`` or
``"mean ± std"`` (``+-`` also), or ``"± std"`` centred on the machine file's value; mm,
degrees for angle parameters::

    prior:
      L0_*: [640, 0.5]
      b1.z: "± 0.2"

Measurements in several sessions (a ``session`` column; each session its own sensor
parameters ``NAME@LABEL``, :mod:`pkmcal.sensors.sessions`) may have re-homed actuators
between sessions: ``sessions: {actuator_offsets: true}`` estimates zero offsets
``dq_i@LABEL`` for every session but the first. ``sessions:`` may also give the sensor of
named sessions (``"2": {world: {x: 1.5, ...}}``, as the calibrated file's ``setup:`` writes
them), the starting values of those sessions.

Built-in setups (:data:`pkmcal.sensors.library.BUILTIN_SETUPS`, re-exported here) are usable by
name wherever a setup file is. A planar-tool setup is bound to its machine's pose dimension
(2 or 3) by :func:`bind_setup` (``load_setup(path, machine)`` does it).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Annotated, Any, Callable, Literal, Union

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, StrictFloat, StrictStr, ValidationError, field_validator

from pkmcal.errors import InputFileError, PkmcalError, line_problem
from pkmcal.io._yaml import (
    FlowList,
    RawFloat,
    YamlSyntaxError,
    deg_to_rad,
    dump_yaml,
    parse_yaml,
    plain,
    rad_to_deg_text,
)
from pkmcal.io.atomic import atomic_write_text
from pkmcal.io.inputs import read_input_text
from pkmcal.io.limits import MAX_DESCRIPTION_CHARS, magnitude_problem
from pkmcal.io.lookup import load_setup  # noqa: F401  (re-exported: the front door lives in io.lookup)
from pkmcal.mechanisms.statics import StaticsModel
from pkmcal.sensors import (
    DistanceSensor,
    FullPoseSensor,
    IndicatorSensor,
    MeasurementSetup,
    NoiseModel,
    PlanarToolSensor,
    PositionSensor,
)
from pkmcal.sensors.library import (  # noqa: F401  (re-exported: the built-ins used to live here)
    BUILTIN_SETUPS,
    PLANAR_ACTUATORS,
    PLANAR_LOAD,
    PLANAR_TRACKER_STD,
    PROTOTYPE_INDICATORS,
    SQRT3,
    bind_setup,
    builtin_setup,
)
from pkmcal.sensors.printed_distance import PrintedDistanceSensor
from pkmcal.sensors.z_probe import MAX_BED_TILT_DEG, ZProbeSensor

def _plausible(v: float) -> float:
    problem = magnitude_problem(float(v), None)
    if problem is not None:
        raise ValueError(problem)
    return v


def _one_line(v: str) -> str:
    problem = line_problem(v, MAX_DESCRIPTION_CHARS)
    if problem is not None:
        raise ValueError(problem)
    return v


#: A number as written: an integer or a float, never a boolean or a quoted text (no
#: coercion: ``true`` or ``'0.01'`` is an error), finite and within ±1e6 (:mod:`pkmcal.io.limits`).
Number = Annotated[StrictFloat, AfterValidator(_plausible)]
Values = Union[Number, list[Number]]
def _stiffness(v: float) -> float:
    if not MIN_STIFFNESS <= v <= MAX_STIFFNESS:
        raise ValueError(f"{v!r} is not an actuator stiffness: give {MIN_STIFFNESS:g} to {MAX_STIFFNESS:g} "
                         "(N/mm, or N*mm/rad for rotary actuators)")
    return v


def _load(v: float) -> float:
    if not abs(v) <= MAX_LOAD:
        raise ValueError(f"{v!r} N is not a tool load: give at most {MAX_LOAD:g} N")
    return v


#: Plausible actuator stiffnesses (N/mm or N·mm/rad) and tool loads (N): beyond them the
#: static equilibrium's matrices (K Jᵀ J) overflow or lose every digit.
MIN_STIFFNESS, MAX_STIFFNESS, MAX_LOAD = 1e-6, 1e12, 1e9
Stiffness = Annotated[StrictFloat, AfterValidator(_stiffness)]
Load = Annotated[StrictFloat, AfterValidator(_load)]
#: Largest accepted noise value (mm, rad, deg): beyond it the weights 1/σ² underflow.
MAX_NOISE_STD = 1e6


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)


class _Transform(_Strict):
    """A pose x, y, z (mm), a, b, c (degrees); missing coordinates are 0."""

    x: Number = 0.0
    y: Number = 0.0
    z: Number = 0.0
    a: Number = 0.0
    b: Number = 0.0
    c: Number = 0.0


class _Point(_Strict):
    x: Number = 0.0
    y: Number = 0.0
    z: Number = 0.0


class _Noise(_Strict):
    distribution: Literal["gaussian", "uniform"] = "gaussian"
    reading: Values | None = None
    position: Values | None = None
    orientation: Values | None = None
    orientation_deg: Values | None = None
    actuator: Values

    @field_validator("reading", "position", "orientation", "orientation_deg", "actuator")
    @classmethod
    def _non_negative(cls, v):
        vals = v if isinstance(v, list) else [v]
        if v is not None and (not vals or any(not math.isfinite(x) or x < 0 or x > MAX_NOISE_STD for x in vals)):
            raise ValueError(f"must be a non-negative number (at most {MAX_NOISE_STD:g}) or a non-empty list of them")
        return v


class _Simulation(_Strict):
    stiffness: Union[Stiffness, list[Stiffness]]
    load: tuple[Load, Load] | None = None
    backlash: Values | None = None


class _Bed(_Strict):
    """The z-probe's bed plane: height z (mm), tilts a, b (degrees, within ±45)."""

    z: Number = 0.0
    a: Number = 0.0
    b: Number = 0.0

    @field_validator("a", "b")
    @classmethod
    def _a_bed(cls, v):
        if not abs(v) <= MAX_BED_TILT_DEG:
            raise ValueError(f"a bed tilt of {v!r} deg is not a bed; give at most {MAX_BED_TILT_DEG:g} deg")
        return v


class _Setup(_Strict):
    sensor: Any     # a registered sensor kind (:data:`_SENSOR_KINDS`), checked by _known_kind
    description: Annotated[StrictStr, AfterValidator(_one_line)] = ""
    indicators: list[tuple[Number, Number]] | None = None
    plane_offset: Number | None = None
    zero: list[Number] | None = None
    plate: _Transform | None = None
    world: _Transform | None = None
    tool: _Transform | None = None
    target: _Point | None = None
    pivots: list[tuple[Number, Number, Number]] | None = None
    ball: _Point | None = None
    lengths: list[Number] | None = None
    probe_offset: tuple[Number, Number, Number] | None = None
    bed: _Bed | None = None
    free: list[StrictStr] | None = None
    noise: _Noise
    simulation: _Simulation | None = None
    prior: dict[StrictStr, Union[tuple[Number, Number], StrictStr]] | None = None
    sessions: dict | None = None    # checked by _sessions (labels are free text)

    @field_validator("sensor")
    @classmethod
    def _known_kind(cls, v):
        if not isinstance(v, str) or v not in _SENSOR_KINDS:
            raise ValueError(f"must be one of {', '.join(_SENSOR_KINDS)}")
        return v

    @field_validator("free")
    @classmethod
    def _each_once(cls, v):
        if v is not None:
            twice = next((n for i, n in enumerate(v) if n in v[:i]), None)
            if twice is not None:
                raise ValueError(f"'{twice}' is listed twice; list each parameter once")
        return v


@dataclass(frozen=True)
class SensorFileKind:
    """One ``sensor:`` kind of setup files, as the registry holds it: its own setup keys
    (``keys``, fields of the setup schema besides ``sensor``, ``description``, ``free``,
    ``noise``, ``prior``, ``sessions``) and noise keys (``noise_keys``, besides
    ``actuator``); ``read(ctx)`` → (sensor in file units, reading std (m,)) from a
    :class:`SetupReading`; ``write(sensor)`` → its keys (exact floats, file units);
    ``write_noise(std, uniform)`` → its noise keys; ``simulation``: the setup may carry the
    statics of ``pkmcal simulate``/``verify`` (``simulation:``)."""

    kind: str
    keys: tuple[str, ...]
    read: Callable[["SetupReading"], tuple[Any, np.ndarray]]
    write: Callable[[Any], dict]
    noise_keys: tuple[str, ...] = ("reading",)
    write_noise: Callable[[np.ndarray, bool], dict] | None = None
    simulation: bool = False


#: The registry: ``sensor:`` kind → :class:`SensorFileKind`, in the order errors list them.
_SENSOR_KINDS: dict[str, SensorFileKind] = {}


def register_sensor_kind(entry: SensorFileKind) -> SensorFileKind:
    """Add a ``sensor:`` kind to setup files: :func:`load_setup` and :func:`setup_to_dict`
    read and write it with ``entry`` and need nothing else. Its ``keys`` must be keys of
    the setup schema (:class:`_Setup`): a new key is added there."""
    unknown = [k for k in entry.keys if k not in _Setup.model_fields]
    if unknown:
        raise ValueError(f"sensor kind '{entry.kind}': {', '.join(unknown)} not setup keys; add them to _Setup")
    _SENSOR_KINDS[entry.kind] = entry
    return entry


def sensor_kinds() -> tuple[str, ...]:
    """Every ``sensor:`` kind a setup file may give."""
    return tuple(_SENSOR_KINDS)


# -- loading -----------------------------------------------------------------------------


def _line_of(lines: dict[tuple, int], loc: tuple) -> int | None:
    """Line of the longest prefix of ``loc`` that is a key path of the document."""
    path: tuple = ()
    best = lines.get(())
    for part in loc:
        if (path + (part,)) in lines:
            path = path + (part,)
            best = lines[path]
        elif isinstance(part, str) and part in ("float", "list[float]", "tuple[float, float]"):
            continue  # pydantic names union members in its locations; skip them
        else:
            break
    return best


def _key_text(loc: tuple) -> str:
    parts = [p for p in loc if not (isinstance(p, str) and ("[" in p or p in ("float", "int")))]
    text = ""
    for p in parts:
        p = p if isinstance(p, int) or str(p).isprintable() else repr(p)[1:-1]  # one line, even for 'a\nb'
        text += f"[{p}]" if isinstance(p, int) else (f".{p}" if text else str(p))
    return text or "(top level)"


def _fail(path, lines, loc: tuple, message: str):
    raise InputFileError(path, f"key '{_key_text(loc)}': {message}", line=_line_of(lines, loc))


def _expand(path, lines, value, n: int, loc: tuple, unit: str) -> np.ndarray:
    """One value or n values → array (n,)."""
    if isinstance(value, list):
        if len(value) != n:
            _fail(path, lines, loc, f"give one value or {n} values ({unit}); got {len(value)}")
        return np.array(value, dtype=float)
    return np.full(n, float(value))


def read_setup_file(path: str | os.PathLike, machine=None) -> MeasurementSetup:
    """The measurement setup of the YAML file ``path`` (it exists; a built-in name is
    resolved by :func:`pkmcal.io.lookup.load_setup`, re-exported here as ``load_setup``);
    bound to ``machine`` (:func:`bind_setup`) when one is given.

    Raises :class:`~pkmcal.errors.InputFileError` naming the file, line and key.
    """
    text = read_input_text(path, "setup file", fix="save it as UTF-8 YAML")
    try:
        data, lines = parse_yaml(text)
    except YamlSyntaxError as exc:
        raise InputFileError(path, str(exc), line=exc.line) from None
    if not isinstance(data, dict):
        raise InputFileError(path, f"a setup file is a YAML mapping starting with 'sensor: {'|'.join(_SENSOR_KINDS)}'")
    data, lines = _setup_mapping(path, data, lines)
    try:
        spec = _Setup.model_validate(data)
    except ValidationError as exc:
        errs = exc.errors()
        err = next((e for e in errs if e["type"] == "extra_forbidden"), errs[0])  # a misspelt key first
        loc = tuple(err["loc"])
        if err["type"] == "missing":
            what = "is missing" + (
                f"; say which sensor: one of {', '.join(_SENSOR_KINDS)}" if loc == ("sensor",)
                else "; give the actuator noise (mm), e.g. noise: {reading: 0.01, actuator: 0.005}"
                if loc == ("noise", "actuator") else
                "; give the actuator stiffness, e.g. simulation: {stiffness: 2.0e4, load: [0, -30]} "
                "(N/mm or N*mm/rad; N)" if loc == ("simulation", "stiffness") else "")
        elif err["type"] == "extra_forbidden":
            model = {(): _Setup, ("noise",): _Noise, ("world",): _Transform, ("tool",): _Transform, ("plate",): _Transform,
                     ("target",): _Point, ("simulation",): _Simulation, ("bed",): _Bed}.get(loc[:-1], _Setup)
            what = f"is not a setup key here; remove or correct it (allowed: {', '.join(model.model_fields)})"
        else:
            what = describe_error(err)
        _fail(path, lines, loc, what)
    setup = _build(path, lines, spec, data)
    if spec.prior:
        import dataclasses

        setup = dataclasses.replace(setup, priors=_priors(path, lines, spec.prior))
    setup = setup if machine is None else bind_setup(setup, machine, path)
    return setup if spec.sessions is None else _sessions(path, lines, spec.sessions, setup)


def _sessions(path, lines, sessions: dict, setup: MeasurementSetup) -> MeasurementSetup:
    """The setup with its ``sessions:`` mapping (several measurement sessions,
    :mod:`pkmcal.sensors.sessions`): ``actuator_offsets: true|false`` (re-homing offsets for
    the sessions after the first), and ``LABEL: {world: {...}, tool: {...}, zero: [...], ...}``
    the sensor of a named session (a calibrated file's identified sessions; file units),
    the starting values of that session when the measurements have it. A ``dq`` list there
    (identified offsets) is information: offsets start from 0."""
    import dataclasses

    from pkmcal.sensors.sessions import sensor_from_values

    offsets = sessions.get("actuator_offsets", False)
    if not isinstance(offsets, bool):
        _fail(path, lines, ("sessions", "actuator_offsets"), f"must be true or false; got {offsets!r}")
    named = []
    for label, values in sessions.items():
        if label == "actuator_offsets":
            continue
        if not isinstance(values, dict):
            _fail(path, lines, ("sessions", label), "give the session's sensor parameters as a mapping "
                  "(e.g. world: {x: 0, y: 0, z: 0, a: 0, b: 0, c: 0}), or actuator_offsets: true|false")
        try:
            named.append((str(label), sensor_from_values(setup.sensor, values, deg_to_rad)))
        except PkmcalError as exc:
            _fail(path, lines, ("sessions", label), str(exc))
    return dataclasses.replace(setup, session_offsets=offsets, session_sensors=tuple(named))


#: Keys of a machine file (any kind) that a setup file never has: a file with one of them
#: and no ``sensor:`` is a machine file, whose identified ``setup:`` is the setup.
_MACHINE_KEYS = ("kind", "legs", "towers", "arms", "parameters", "calibration", "uncertainty", "setup")
#: Keys of the identified setup in a calibrated machine file that are not setup-file keys:
#: the 1σ of the estimated sensor parameters and which covariance they come from.
IDENTIFIED_KEYS = ("std", "covariance_kind")


def _setup_mapping(path, data: dict, lines: dict) -> tuple[dict, dict]:
    """The setup mapping of a parsed file and its key-path → line map: the file itself for
    a setup file; the ``setup:`` mapping of a calibrated machine file (``pkmcal identify``
    writes it: docs/file-formats.md), without its :data:`IDENTIFIED_KEYS`, whose ``std``
    names are checked here. A machine file without ``setup:`` is an error naming it."""
    if "sensor" in data or not any(k in data for k in _MACHINE_KEYS):
        return data, lines
    block = data.get("setup")
    if block is None:
        raise InputFileError(path, "is a machine file without an identified setup: give the measurement setup "
                                   "(a setup file or a built-in name), or a machine file that 'pkmcal identify' "
                                   "wrote for a setup with sensor parameters", line=lines.get(()))
    if not isinstance(block, dict):
        raise InputFileError(path, "key 'setup': expected the identified setup, a mapping 'sensor: ...' as in a "
                                   "setup file", line=lines.get(("setup",)))
    sub = {k[1:]: v for k, v in lines.items() if k[:1] == ("setup",)}
    std = block.get("std")
    if std is not None and (not isinstance(std, dict) or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0
            for v in std.values())):
        raise InputFileError(path, "key 'setup.std': expected a mapping 'parameter: standard deviation' "
                                   "(mm, degrees; non-negative numbers)", line=sub.get(("std",)))
    kind = block.get("covariance_kind")
    if kind is not None and not isinstance(kind, str):
        raise InputFileError(path, "key 'setup.covariance_kind': expected text (which covariance 'std' is from)",
                             line=sub.get(("covariance_kind",)))
    return {k: v for k, v in block.items() if k not in IDENTIFIED_KEYS}, sub


def _priors(path, lines, prior: dict) -> tuple:
    """The ``prior:`` mapping as :class:`~pkmcal.prior.Prior` objects
    (file units; each names the file and line it came from, for later errors)."""
    from pkmcal.prior import Prior, parse_value

    out = []
    for pattern, value in prior.items():
        line = _line_of(lines, ("prior", pattern))
        source = f"{path}, line {line}" if line is not None else str(path)
        try:
            out.append(parse_value(value, pattern, source, str(path)) if isinstance(value, str) else
                       Prior(pattern, float(value[0]), float(value[1]), source, str(path)))
        except PkmcalError as exc:
            _fail(path, lines, ("prior", pattern), str(exc).split("): ", 1)[-1])
    return tuple(out)


def describe_error(err: dict) -> str:
    """One pydantic error of a strict schema (a setup or study file) in the file's words (no
    coercion happens: say what was given)."""
    kind, value = err["type"], plain(err.get("input"))
    shown = {True: "true", False: "false", None: "null"}.get(value, repr(value)) if not isinstance(
        value, (list, dict, float, int)) or isinstance(value, bool) else repr(value)
    shown = shown if len(shown) <= 60 else shown[:57] + "..."
    why = ("; true/false is not a number" if isinstance(value, bool) else
           "; it is quoted text: remove the quotes" if isinstance(value, str) else "")
    if kind == "float_type":
        return f"expected a number, got {shown}{why}"
    if kind in ("int_type", "int_from_float"):
        return f"expected a whole number, got {shown}{why}"
    if kind == "bool_type":
        return f"expected true or false, got {shown}"
    if kind == "finite_number":
        return f"expected a finite number, got {shown}"
    if kind == "string_type":
        return f"expected text, got {shown}; quote it if it looks like a number"
    if kind in ("list_type", "tuple_type"):
        return f"expected a list, got {shown}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return f"expected a mapping of 'key: value' entries, got {shown}"
    if kind == "value_error":
        return err["msg"].removeprefix("Value error, ")
    return err["msg"][0].lower() + err["msg"][1:]


def _build(path, lines, spec: _Setup, raw: dict | None = None) -> MeasurementSetup:
    """The setup of a validated file; ``raw`` the file's mapping as parsed (its numbers keep
    their text, which pydantic drops: degree values are converted from that text, so that
    a setup written by :func:`setup_to_yaml` reads back exactly)."""
    raw = raw if isinstance(raw, dict) else {}
    raw_noise = raw.get("noise") if isinstance(raw.get("noise"), dict) else {}
    entry = _SENSOR_KINDS[spec.sensor]
    kind = entry.kind
    sensor_keys = {k for e in _SENSOR_KINDS.values() for k in e.keys}
    for key in (k for k in _Setup.model_fields if k in sensor_keys):   # in the schema's order
        if getattr(spec, key) is not None and key not in entry.keys:
            _fail(path, lines, (key,), f"does not apply to sensor '{kind}' (its keys: {', '.join(entry.keys)})")
    noise = spec.noise
    for key in ("reading", "position", "orientation", "orientation_deg"):
        if getattr(noise, key) is not None and key not in entry.noise_keys:
            _fail(path, lines, ("noise", key),
                  f"does not apply to sensor '{kind}' (its noise keys: {', '.join(entry.noise_keys)}, actuator)")
    ctx = SetupReading(path=path, lines=lines, spec=spec, noise=noise, raw_noise=raw_noise,
                       free=None if spec.free is None else tuple(spec.free))
    try:
        sensor, reading_std = entry.read(ctx)
        sensor = _from_file_units(sensor, raw)
    except InputFileError:
        raise
    except PkmcalError as exc:  # e.g. an unknown name in free:
        _fail(path, lines, ("free",) if "no parameter" in str(exc) else (), str(exc))
    actuator = np.array(noise.actuator, dtype=float)
    if noise.distribution == "uniform":  # half-widths h → std h/√3
        reading_std, actuator = reading_std / SQRT3, actuator / SQRT3
    simulation = None
    if spec.simulation is not None:
        if not entry.simulation:
            _fail(path, lines, ("simulation",), "applies to redundantly actuated planar machines (sensor: planar-tool) "
                  "only; remove it")
        try:
            backlash = spec.simulation.backlash
            simulation = StaticsModel(stiffness=np.array(spec.simulation.stiffness, dtype=float),
                                      load=None if spec.simulation.load is None else np.array(spec.simulation.load),
                                      backlash=None if backlash is None else np.array(backlash, dtype=float))
        except PkmcalError as exc:
            key = next((k for k in ("stiffness", "load", "backlash") if k in str(exc)), "stiffness")
            _fail(path, lines, ("simulation", key), str(exc))
    return MeasurementSetup(
        sensor=sensor,
        noise=NoiseModel(reading_std=reading_std, actuator_std=actuator, distribution=noise.distribution),
        simulation=simulation,
    )


def _from_file_units(sensor, raw: dict | None = None):
    """``sensor``, built with θ as the file gives it (mm, degrees), with the parameters its
    ``param_is_angle`` declares angles converted to radians (:func:`deg_to_rad`). ``raw``
    is the file's mapping as parsed: an angle ``world.a`` is converted from the text of
    ``raw['world']['a']`` when there is one (pydantic keeps only the float), so that the
    degree text :func:`setup_to_yaml` writes reads back to the same radians exactly."""
    raw = raw or {}

    def source(name: str, v: float):
        group, _, coord = name.partition(".")
        block = raw.get(group)
        text_value = block.get(coord) if coord and isinstance(block, dict) else None
        return text_value if isinstance(text_value, float) and float(text_value) == float(v) else v

    theta = [deg_to_rad(source(n, v)) if ang else float(v)
             for n, v, ang in zip(sensor.param_names, sensor.params, sensor.param_is_angle)]
    return sensor.with_params(np.array(theta))


# -- saving ------------------------------------------------------------------------------


def _half_width(std: float) -> float:
    """The half-width h whose h/√3 is ``std`` exactly when one is within a few ulps, so
    that a uniform setup reads back bit for bit."""
    h = std * SQRT3
    for k in range(5):
        for direction in (math.inf, -math.inf):
            w = h
            for _ in range(k):
                w = math.nextafter(w, direction)
            if w / SQRT3 == std:
                return w
    return h


def _values(std: np.ndarray, uniform: bool):
    v = np.asarray(std, dtype=float).reshape(-1)
    if uniform:
        v = np.array([_half_width(float(x)) for x in v])
    if v.size == 1 or np.all(v == v[0]):
        return float(v[0])
    return FlowList(float(x) for x in v)


def _values_deg(std_rad: np.ndarray, uniform: bool):
    """:func:`_values` of angles given in radians, written in degrees (the text that reads
    back to the same radians exactly, :func:`rad_to_deg_text`)."""
    v = np.asarray(std_rad, dtype=float).reshape(-1)
    if uniform:
        v = np.array([_half_width(float(x)) for x in v])
    if v.size == 1 or np.all(v == v[0]):
        return RawFloat(rad_to_deg_text(float(v[0])))
    return FlowList(RawFloat(rad_to_deg_text(float(x))) for x in v)


def _group_dict(sensor, field: str) -> dict:
    """The mapping written for the θ field ``field`` of ``sensor`` (``world``, ``tool``,
    ``target``): keys the parameter names after the dot (``world.c`` → ``c``), values in file
    units, degrees for the parameters the sensor's ``param_groups`` declare angles."""
    group = next(g for g in sensor.param_groups if g.field == field)
    return {name.split(".", 1)[1]: RawFloat(rad_to_deg_text(v)) if ang else float(v)
            for name, v, ang in zip(group.names, getattr(sensor, field), group.is_angle)}


def setup_to_yaml(setup: MeasurementSetup) -> str:
    """YAML text of a setup (full precision; :func:`load_setup` reads it back)."""
    head = "# pkmcal measurement setup: mm, angles in degrees (transforms, orientation_deg noise)\n"
    if setup.noise.distribution == "uniform":
        head += "# uniform noise: values are half-widths h (std = h/sqrt(3))\n"
    return head + dump_yaml(setup_to_dict(setup))


def identified_setup(setup: MeasurementSetup, sensor, std: dict[str, float] | None = None,
                     covariance_kind: str | None = None) -> dict:
    """The ``setup:`` mapping of a calibrated machine file: ``setup`` with the identified
    ``sensor`` in setup-file form (:func:`setup_to_dict`: mm, degrees), plus ``std`` (1σ of
    the estimated sensor parameters, internal units in ``std`` → mm / degrees in the file)
    and ``covariance_kind`` (which covariance those σ are, the words of the fit's
    ``calibration.std``). :func:`load_setup` of the machine file reads it back as a setup
    with ``sensor`` exactly."""
    import dataclasses

    doc = setup_to_dict(dataclasses.replace(setup, sensor=sensor))
    if std:
        angles = {n for n, a in zip(sensor.param_names, sensor.param_is_angle) if a}
        doc["std"] = {n: float(np.rad2deg(v)) if n in angles else float(v) for n, v in std.items()}
    if covariance_kind is not None:
        doc["covariance_kind"] = str(covariance_kind)
    return doc


def setup_to_dict(setup: MeasurementSetup) -> dict:
    """The mapping of a setup file for ``setup`` (exact floats; :func:`setup_to_yaml` dumps it)."""
    s, noise = setup.sensor, setup.noise
    doc: dict = {"sensor": s.kind}
    entry = _SENSOR_KINDS.get(s.kind)
    if entry is None:
        raise PkmcalError(f"cannot save a setup with a '{s.kind}' sensor")
    doc.update(entry.write(s))
    if s.free is not None:
        doc["free"] = FlowList(s.free)
    uniform = noise.distribution == "uniform"
    nd: dict = {"distribution": noise.distribution}
    std = np.asarray(noise.reading_std, dtype=float).reshape(-1)
    nd.update((entry.write_noise or _reading_noise)(std, uniform))
    nd["actuator"] = _values(noise.actuator_std, uniform)
    doc["noise"] = nd
    if setup.simulation is not None:
        sim: dict = {"stiffness": _values(setup.simulation.stiffness, False)}
        if setup.simulation.load is not None:
            sim["load"] = FlowList(float(v) for v in setup.simulation.load)
        if setup.simulation.backlash is not None:
            sim["backlash"] = _values(setup.simulation.backlash, False)
        doc["simulation"] = sim
    if setup.priors:
        doc["prior"] = {p.pattern: (f"± {p.std!r}" if p.mean is None else FlowList([float(p.mean), float(p.std)]))
                        for p in setup.priors}
    return doc


def _reading_noise(std: np.ndarray, uniform: bool) -> dict:
    """The noise key of most sensors: ``reading`` (one value or one per reading)."""
    return {"reading": _values(std, uniform)}


# -- sensor kinds: each registers its reader and writer (the obvious place for a new kind) ----


@dataclass(frozen=True)
class SetupReading:
    """What a kind's reader gets: the file (``path``, ``lines`` for errors), the validated
    setup ``spec`` and its ``noise``, the noise mapping as parsed (``raw_noise``: numbers
    with their text) and the ``free`` names."""

    path: object
    lines: dict
    spec: _Setup
    noise: _Noise
    raw_noise: dict
    free: tuple[str, ...] | None

    def fail(self, loc: tuple, message: str):
        """Raise the :class:`InputFileError` of key ``loc``."""
        _fail(self.path, self.lines, loc, message)

    def expand(self, value, n: int, loc: tuple, unit: str) -> np.ndarray:
        """One value or n values → array (n,)."""
        return _expand(self.path, self.lines, value, n, loc, unit)

    def reading_std(self, n: int, what: str) -> np.ndarray:
        """``noise.reading`` for ``n`` readings (mm); missing: an error naming ``what``."""
        if self.noise.reading is None:
            self.fail(("noise", "reading"), f"is missing; give {what}")
        return self.expand(self.noise.reading, n, ("noise", "reading"), "mm")


def _pose6(t: _Transform | None):
    """x, y, z, a, b, c as written (mm, degrees); :func:`_from_file_units` converts."""
    return None if t is None else np.array([t.x, t.y, t.z, t.a, t.b, t.c])


def _read_full_pose(ctx: SetupReading):
    spec, noise = ctx.spec, ctx.noise
    sensor = FullPoseSensor(world=_pose6(spec.world), tool=_pose6(spec.tool), free=ctx.free)
    if noise.position is None:
        ctx.fail(("noise", "position"), "is missing; give the position noise (mm)")
    if (noise.orientation is None) == (noise.orientation_deg is None):
        ctx.fail(("noise", "orientation"), "give exactly one of orientation (rad) or orientation_deg (degrees)")
    pos = ctx.expand(noise.position, 3, ("noise", "position"), "mm")
    if noise.orientation is not None:
        ori = ctx.expand(noise.orientation, 3, ("noise", "orientation"), "rad")
    else:
        raw_ori = (ctx.raw_noise or {}).get("orientation_deg", noise.orientation_deg)   # numbers with their text
        ctx.expand(raw_ori, 3, ("noise", "orientation_deg"), "deg")   # checks the count
        ori = np.broadcast_to(np.array([deg_to_rad(v) for v in
                                        (raw_ori if isinstance(raw_ori, list) else [raw_ori])]), (3,)).copy()
    return sensor, np.concatenate([pos, ori])


def _write_full_pose(s: FullPoseSensor) -> dict:
    doc: dict = {}
    if np.any(s.world != 0):
        doc["world"] = _group_dict(s, "world")
    if np.any(s.tool != 0):
        doc["tool"] = _group_dict(s, "tool")
    return doc


def _full_pose_noise(std: np.ndarray, uniform: bool) -> dict:
    return {"position": _values(std[:3], uniform), "orientation_deg": _values_deg(std[3:], uniform)}


def _read_position(ctx: SetupReading):
    spec = ctx.spec
    target = None if spec.target is None else [spec.target.x, spec.target.y, spec.target.z]
    sensor = PositionSensor(target=target, world=_pose6(spec.world), free=ctx.free)
    return sensor, ctx.reading_std(3, "the tracker noise (mm)")


def _write_target_world(s) -> dict:
    """``target`` and, unless 0, ``world`` (the position and planar-tool trackers)."""
    doc: dict = {"target": _group_dict(s, "target")}
    if np.any(s.world != 0):
        doc["world"] = _group_dict(s, "world")
    return doc


def _read_indicators(ctx: SetupReading):
    spec = ctx.spec
    if spec.indicators is None:
        ctx.fail(("indicators",), "is missing; give the indicator positions [[x, y], ...] in mm (base frame), at least 3")
    if spec.plane_offset is None:
        ctx.fail(("plane_offset",), "is missing; give the distance (mm) of the platform origin above the platform's "
                 "lower plane touched by the indicators")
    if len(spec.indicators) < 3:
        ctx.fail(("indicators",), f"needs at least 3 indicators; got {len(spec.indicators)}")
    k = len(spec.indicators)
    if spec.zero is not None and len(spec.zero) != k:
        ctx.fail(("zero",), f"give one zero offset per indicator ({k}); got {len(spec.zero)}")
    sensor = IndicatorSensor(positions=np.array(spec.indicators, dtype=float), plane_offset=spec.plane_offset,
                             zero=spec.zero, plate=_pose6(spec.plate), free=ctx.free)
    return sensor, ctx.reading_std(k, "the indicator noise (mm)")


def _write_indicators(s: IndicatorSensor) -> dict:
    doc: dict = {"indicators": [FlowList(float(v) for v in row) for row in s.positions],
                 "plane_offset": float(s.plane_offset)}
    if np.any(s.zero != 0):
        doc["zero"] = FlowList(float(v) for v in s.zero)
    if not s.plate_is_identity:
        doc["plate"] = _group_dict(s, "plate")
    return doc


def _read_planar_tool(ctx: SetupReading):
    spec = ctx.spec
    if spec.target is not None and spec.target.z != 0:
        ctx.fail(("target", "z"), "a planar tool point has no z; give target: {x, y} (mm)")
    if spec.world is not None:
        for key in ("z", "a", "b"):
            if getattr(spec.world, key) != 0:
                ctx.fail(("world", key), "a planar tracker frame has only x, y (mm) and c (deg)")
    target = None if spec.target is None else [spec.target.x, spec.target.y]
    world = None if spec.world is None else [spec.world.x, spec.world.y, spec.world.c]
    sensor = PlanarToolSensor(n_pose=2, target=target, world=world, free=ctx.free)
    return sensor, ctx.reading_std(2, "the tracker noise (mm)")


def _read_distance(ctx: SetupReading):
    spec = ctx.spec
    if not spec.pivots:
        ctx.fail(("pivots",), "is missing; give the pivot points [[x, y, z], ...] in mm (base frame), at least one")
    k = len(spec.pivots)
    if spec.lengths is not None and len(spec.lengths) != k:
        ctx.fail(("lengths",), f"give one reference length per pivot ({k}); got {len(spec.lengths)}")
    ball = None if spec.ball is None else [spec.ball.x, spec.ball.y, spec.ball.z]
    sensor = DistanceSensor(pivots=np.array(spec.pivots, dtype=float), ball=ball, lengths=spec.lengths, free=ctx.free)
    return sensor, ctx.reading_std(k, "the distance noise (mm)")


def _write_distance(s: DistanceSensor) -> dict:
    """``pivots``, ``ball`` and, unless 0, ``lengths`` (mm)."""
    doc: dict = {"pivots": [FlowList(float(v) for v in row) for row in s.pivots.reshape(-1, 3)],
                 "ball": _group_dict(s, "ball")}
    if np.any(s.lengths != 0):
        doc["lengths"] = FlowList(float(v) for v in s.lengths)
    return doc


def _read_z_probe(ctx: SetupReading):
    spec = ctx.spec
    bed = None if spec.bed is None else [spec.bed.z, spec.bed.a, spec.bed.b]
    sensor = ZProbeSensor(probe_offset=spec.probe_offset, bed=bed, free=ctx.free)
    return sensor, ctx.reading_std(1, "the probe's trigger noise (mm), e.g. the standard deviation "
                                      "PROBE_ACCURACY reports")


def _read_printed_distance(ctx: SetupReading):
    spec = ctx.spec
    bed = None if spec.bed is None else [spec.bed.z, spec.bed.a, spec.bed.b]
    sensor = PrintedDistanceSensor(probe_offset=spec.probe_offset, bed=bed, free=ctx.free)
    return sensor, ctx.reading_std(2, "the probe's trigger noise and the calipers' (mm), e.g. [0.005, 0.02]")


def _write_z_probe(s: ZProbeSensor) -> dict:
    """``probe_offset`` (mm) and, unless 0, ``bed`` (mm, degrees)."""
    doc: dict = {"probe_offset": FlowList(float(v) for v in s.probe_offset)}
    if np.any(s.bed != 0):
        doc["bed"] = _group_dict(s, "bed")
    return doc


# The built-in kinds, in the order errors list them. A new kind: its reader and writer above,
# its keys in _Setup when new, and one line here.
register_sensor_kind(SensorFileKind(FullPoseSensor.kind, ("world", "tool"), _read_full_pose, _write_full_pose,
                                    noise_keys=("position", "orientation", "orientation_deg"),
                                    write_noise=_full_pose_noise))
register_sensor_kind(SensorFileKind(PositionSensor.kind, ("target", "world"), _read_position, _write_target_world))
register_sensor_kind(SensorFileKind(IndicatorSensor.kind, ("indicators", "plane_offset", "zero", "plate"),
                                    _read_indicators, _write_indicators))
register_sensor_kind(SensorFileKind(PlanarToolSensor.kind, ("target", "world"), _read_planar_tool,
                                    _write_target_world, simulation=True))
register_sensor_kind(SensorFileKind(DistanceSensor.kind, ("pivots", "ball", "lengths"), _read_distance,
                                    _write_distance))
register_sensor_kind(SensorFileKind(ZProbeSensor.kind, ("probe_offset", "bed"), _read_z_probe, _write_z_probe))
register_sensor_kind(SensorFileKind(PrintedDistanceSensor.kind, ("probe_offset", "bed"), _read_printed_distance,
                                    _write_z_probe))


def save_setup(setup: MeasurementSetup, path: str | os.PathLike) -> None:
    """Write ``setup`` to ``path`` atomically (see :func:`setup_to_yaml`)."""
    atomic_write_text(path, setup_to_yaml(setup))
