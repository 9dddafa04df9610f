"""Machine files (YAML): load, validate, save. Format: ``docs/file-formats.md``.

A machine file describes one mechanism; ``kind`` (default ``hexapod``) selects the schema
from the registry (:class:`MachineKind`, :func:`register_machine_kind`; the kinds of other
modules are named in :mod:`pkmcal.registry`), by which :func:`machine_from_text` and
:func:`machine_to_text` are generic drivers (docs/architecture.md, "Registries").
The hexapod schema is paper 2's Table 3 layout per leg (base joint b_i, platform joint a_i,
offset L0_i, stroke, and a gain g_i when the readings are not in mm: L_i = L0_i + g_i λ_i,
with the readings' unit in the top-level ``actuator_unit``) plus limits (paper 2 §5), an optional home pose and workspace box, and
for identified machines the parameter covariance written as standard deviations and a
correlation matrix, Σ_ij = σ_i ρ_ij σ_j over the named parameters, zeros elsewhere.

Lengths are mm, angles degrees in the file (radians inside). Every check is done on load
(pydantic v2); an error names the file, the line, the key path (``legs[3].stroke``, with the
1-based leg number), what is wrong and what to do, as :class:`~pkmcal.errors.InputFileError`.
:func:`save_machine` writes atomically and exactly: every float as its shortest repr, angles
as degree texts that convert back to the same radians (:mod:`pkmcal.io._yaml`), so
``load_machine(save_machine(m)) == m`` bit for bit; it checks this before writing.
"""

from __future__ import annotations

import difflib
import os
from dataclasses import dataclass
from importlib import import_module
from pathlib import Path
from typing import Annotated, Any, Callable, Literal, get_args

import numpy as np
import yaml
from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    StrictFloat,
    StrictStr,
    ValidationError,
    WrapValidator,
    field_validator,
)

from pkmcal.errors import InputFileError, PkmcalError, line_problem, one_line, record_source
from pkmcal.covariance import correlation, standard_deviations
from pkmcal.io._yaml import (
    FlowList,
    RawFloat,
    TextFloat,
    YamlSyntaxError,
    deg_to_rad,
    dump_yaml,
    parse_yaml,
    plain,
    rad_to_deg_text,
)
from pkmcal.io.atomic import atomic_write_text
from pkmcal.io.inputs import read_input_text
from pkmcal.io.limits import MAX_DESCRIPTION_CHARS, MAX_NAME_CHARS, magnitude_problem
from pkmcal.io.lookup import load_machine  # noqa: F401  (re-exported: the front door lives in io.lookup)
from pkmcal.mechanisms.base import Mechanism
from pkmcal.mechanisms.hexapod import DEFAULT_ACTUATOR_UNIT, HEXAPOD_PARAM_NAMES, N_LEGS, Hexapod, HexapodLimits
from pkmcal.registry import MACHINE_FILE_MODULES, PARAMETER_FILE_KINDS

MACHINE_FILE_SUFFIXES = (".yaml", ".yml")
_MAX_FILE_BYTES = 50_000_000


# -- schema -------------------------------------------------------------------------------

def _keep_text(value: Any, handler: Callable[[Any], float]) -> float:
    out = handler(value)
    if isinstance(value, TextFloat) and out == float(value):
        return TextFloat(out, value.text)
    return out


def _plausible(unit: str) -> Callable[[float], float]:
    def check(v: float) -> float:
        problem = magnitude_problem(float(v), unit)
        if problem is not None:
            raise ValueError(problem)
        return v
    return check


def _one_line(max_chars: int) -> Callable[[str], str]:
    def check(v: str) -> str:
        problem = line_problem(v, max_chars)
        if problem is not None:
            raise ValueError(problem)
        return v
    return check


Num = StrictFloat
#: A length or a coordinate (mm), of a plausible size (:mod:`pkmcal.io.limits`).
Length = Annotated[StrictFloat, AfterValidator(_plausible("mm"))]
#: An angle in degrees; remembers its text for the exact conversion (:func:`deg_to_rad`).
Deg = Annotated[StrictFloat, WrapValidator(_keep_text), AfterValidator(_plausible("deg"))]
Vec3 = tuple[Length, Length, Length]
#: A machine's name and description: one line of text (:func:`pkmcal.errors.line_problem`).
Name = Annotated[StrictStr, AfterValidator(_one_line(MAX_NAME_CHARS))]
Description = Annotated[StrictStr, AfterValidator(_one_line(MAX_DESCRIPTION_CHARS))]
#: Longest ``actuator_unit`` text (a unit name: mm, rev, deg, count, "motor rev").
MAX_UNIT_CHARS = 40


def _unit_text(v: str) -> str:
    problem = line_problem(v, MAX_UNIT_CHARS)
    if problem is not None:
        raise ValueError(problem)
    if not v.strip() or v != v.strip():
        raise ValueError(f"{v!r} is not a unit name: give the readings' unit as text without surrounding blanks, "
                         "e.g. mm, rev, deg or count")
    return v


#: The unit of a hexapod's readings and stroke (text; a label, never converted).
ActuatorUnit = Annotated[StrictStr, AfterValidator(_unit_text)]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, frozen=True)


class LegSpec(_Model):
    """One leg: base joint b_i in {F}, platform joint a_i in {P}, offset L0_i (mm), stroke
    (reading units), gain g_i (mm of leg length per reading unit, default 1)."""

    base: Vec3
    platform: Vec3
    offset: Length
    stroke: tuple[Length, Length]
    gain: Annotated[StrictFloat, AfterValidator(_plausible("mm per reading unit"))] = 1.0
    base_axis: Vec3 | None = None
    platform_axis: Vec3 | None = None

    @field_validator("gain")
    @classmethod
    def _positive_gain(cls, v: float) -> float:
        if not v > 0:
            raise ValueError(f"{v!r} is not a leg gain: give the mm of leg length per reading unit, a number > 0 "
                             "(1, or no 'gain:', when the readings are in mm)")
        return v

    @field_validator("offset")
    @classmethod
    def _non_negative_offset(cls, v: float) -> float:
        # L0 = 0 is genhexkins' convention (the reading is the strut length itself)
        if not v >= 0:
            raise ValueError(f"{v!r} mm is not a leg offset: L0 is the leg length at reading 0, give a length >= 0 "
                             "(0 when the readings are the leg lengths themselves, as LinuxCNC's joints)")
        return v

    @field_validator("stroke")
    @classmethod
    def _ordered_stroke(cls, v: tuple[float, float]) -> tuple[float, float]:
        if v[1] < v[0]:
            raise ValueError(f"[{v[0]!r}, {v[1]!r}] has max < min; write it as [min, max]")
        return v

    @field_validator("base_axis", "platform_axis")
    @classmethod
    def _nonzero_axis(cls, v):
        if v is not None and not np.linalg.norm(v) > 1e-12:
            raise ValueError("a joint axis cannot be the zero vector; give its direction, e.g. [0, 0, 1]")
        return v


class LimitsSpec(_Model):
    """Joint tilt limits (degrees), leg diameter (mm) for the collision check, singularity margin."""

    u_joint_tilt: Deg | None = None
    s_joint_tilt: Deg | None = None
    leg_diameter: Length | None = None
    singularity_margin: Num = 0.01

    @field_validator("u_joint_tilt", "s_joint_tilt")
    @classmethod
    def _tilt(cls, v):
        if v is not None and not 0 < v <= 180:
            raise ValueError(f"{float(v)!r}° is not a joint tilt limit: give an angle in (0, 180] degrees, or remove the key")
        return v

    @field_validator("leg_diameter")
    @classmethod
    def _diameter(cls, v):
        if v is not None and v < 0:
            raise ValueError(f"{v!r} mm: a leg diameter cannot be negative")
        return v

    @field_validator("singularity_margin")
    @classmethod
    def _margin(cls, v):
        if not 0 <= v < 1:
            raise ValueError(f"{v!r} is not an inverse condition number margin: give a number in [0, 1)")
        return v


class PoseSpec(_Model):
    """A pose: x, y, z (mm), a, b, c (degrees)."""

    x: Length
    y: Length
    z: Length
    a: Deg
    b: Deg
    c: Deg


def _ordered(v):
    if v[1] < v[0]:
        raise ValueError(f"[{float(v[0])!r}, {float(v[1])!r}] has max < min; write it as [min, max]")
    return v


Range = Annotated[tuple[Length, Length], WrapValidator(lambda v, h: _ordered(h(v)))]
DegRange = Annotated[tuple[Deg, Deg], WrapValidator(lambda v, h: _ordered(h(v)))]


class WorkspaceSpec(_Model):
    """A box [min, max] per pose coordinate (mm, degrees)."""

    x: Range
    y: Range
    z: Range
    a: DegRange
    b: DegRange
    c: DegRange


class UncertaintySpec(_Model):
    """Parameter uncertainty: σ by name (mm), correlation in ``parameters`` order, and
    optionally the exact covariance (mm²) that pkmcal writes alongside them."""

    parameters: list[StrictStr] | None = None
    std: dict[StrictStr, Num]
    correlation: list[list[Num]] | None = None
    covariance: list[list[Num]] | None = None


class HexapodFile(_Model):
    """The ``kind: 6-UPS`` machine file (``kind: hexapod``, the default, is the same kind)."""

    kind: Literal["hexapod", "6-UPS"] = "hexapod"
    name: Name | None = None
    description: Description = ""
    actuator_unit: ActuatorUnit = DEFAULT_ACTUATOR_UNIT
    legs: list[LegSpec]
    limits: LimitsSpec = LimitsSpec()
    home: PoseSpec | None = None
    workspace: WorkspaceSpec | None = None
    uncertainty: UncertaintySpec | None = None
    calibration: dict[StrictStr, Any] | None = None
    metadata: dict[StrictStr, Any] | None = None
    setup: dict[StrictStr, Any] | None = None

    @field_validator("legs", mode="before")
    @classmethod
    def _six_legs(cls, v):
        if isinstance(v, list) and len(v) != N_LEGS:
            raise ValueError(f"{len(v)} legs given, a hexapod needs exactly {N_LEGS}; "
                             f"list one entry per leg, legs 1 to {N_LEGS} in order")
        return v


_EXPECTED_SHAPE = {
    "base": "3 numbers [x, y, z] (mm)", "platform": "3 numbers [x, y, z] (mm)",
    "base_axis": "3 numbers [x, y, z]", "platform_axis": "3 numbers [x, y, z]",
    "stroke": "2 numbers [min, max] (reading units: mm unless 'actuator_unit' says otherwise)",
    "x": "2 numbers [min, max]", "y": "2 numbers [min, max]", "z": "2 numbers [min, max]",
    "a": "2 numbers [min, max]", "b": "2 numbers [min, max]", "c": "2 numbers [min, max]",
}


# -- errors -------------------------------------------------------------------------------

def _key_path(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        elif isinstance(part, str) and part.replace("_", "").isalnum():
            out += ("." if out else "") + part
        else:
            out += f"[{part!r}]"
    if len(loc) >= 2 and loc[0] == "legs" and isinstance(loc[1], int):
        out += f" (leg {loc[1] + 1})"
    return out or "top level"


def _line_of(loc: tuple, lines: dict[tuple, int]) -> int | None:
    for k in range(len(loc), -1, -1):
        if tuple(loc[:k]) in lines:
            return lines[tuple(loc[:k])]
    return None


def _show(value: Any) -> str:
    text = repr(plain(value))
    return text if len(text) <= 60 else text[:57] + "..."


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model inside a field's type (``X``, ``X | None``, ``list[X]``, ``dict[str, X]``)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in get_args(annotation):
        model = _model_in(arg)
        if model is not None:
            return model
    return None


def _keys_at(schema: type[BaseModel], loc: tuple) -> tuple[str, ...]:
    """The keys ``schema`` allows in the mapping at key path ``loc`` (list indices and the
    keys of free mappings, e.g. a delta's tower names, are stepped over)."""
    model = schema
    for part in loc:
        field = model.model_fields.get(part) if isinstance(part, str) else None
        if field is None:
            continue
        model = _model_in(field.annotation)
        if model is None:
            return ()
    return tuple(model.model_fields)


def _describe(err: dict, schema: type[BaseModel]) -> tuple[tuple, str]:
    """``(loc, message)`` of one pydantic error of a file of ``schema``, in the file's words."""
    loc = tuple(p for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    kind, value = err["type"], err.get("input")
    field_name = next((p for p in reversed(loc) if isinstance(p, str)), "")
    if kind == "missing" and loc and isinstance(loc[-1], int):  # a tuple that is too short
        want = _EXPECTED_SHAPE.get(str(field_name), "more items")
        return loc[:-1], f"expected {want}, got {loc[-1]} item{'s' if loc[-1] != 1 else ''}"
    if kind == "missing":
        return loc[:-1], f"missing key '{loc[-1]}'; add it (see docs/file-formats.md)"
    if kind == "extra_forbidden":
        allowed = _keys_at(schema, loc[:-1])
        close = difflib.get_close_matches(str(loc[-1]), allowed, n=1)
        hint = f"did you mean '{close[0]}'? " if close else ""
        return loc, f"unknown key {loc[-1]!r}; {hint}allowed keys here: {', '.join(allowed)}"
    if kind in ("float_type", "float_parsing"):
        return loc, f"expected a number, got {_show(value)}"
    if kind == "finite_number":
        return loc, f"expected a finite number, got {_show(value)}"
    if kind in ("too_short", "too_long"):
        n = (err.get("ctx") or {}).get("actual_length")
        want = _EXPECTED_SHAPE.get(str(field_name), "a different number of items")
        return loc, f"expected {want}, got {n} item{'s' if n != 1 else ''}"
    if kind in ("tuple_type", "list_type"):
        want = _EXPECTED_SHAPE.get(str(field_name), "a list")
        return loc, f"expected a list of {want}, got {_show(value)}" if field_name in _EXPECTED_SHAPE \
            else f"expected a list, got {_show(value)}"
    if kind in ("model_type", "dict_type", "model_attributes_type"):
        return loc, f"expected a mapping of 'key: value' lines, got {_show(value)}"
    if kind == "string_type":
        return loc, f"expected text, got {_show(value)}; quote it if it looks like a number"
    if kind == "literal_error" and loc == ("kind",):
        return loc, f"{_show(value)} is not a known machine kind; known kinds: {', '.join(_KINDS)}"
    if kind == "literal_error":
        return loc, f"expected {(err.get('ctx') or {}).get('expected', 'another value')}, got {_show(value)}"
    if kind == "value_error":
        return loc, err["msg"].removeprefix("Value error, ")
    return loc, f"{err['msg']} (got {_show(value)})"


def _validation_error(path: object, exc: ValidationError, lines: dict[tuple, int],
                      schema: type[BaseModel] | None = None) -> InputFileError:
    """The first problem pydantic found in a file of ``schema`` (default :class:`HexapodFile`),
    in the file's words, with its key path and line."""
    errors = exc.errors(include_url=False)
    # Report the outermost problem first (e.g. the leg count before a leg's contents).
    errors.sort(key=lambda e: len(e["loc"]))
    loc, message = _describe(errors[0], schema or HexapodFile)
    more = f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''})" if len(errors) > 1 else ""
    return InputFileError(path, f"{_key_path(loc)}: {message}{more}", line=_line_of(loc, lines))


# -- hexapod <-> file ---------------------------------------------------------------------

def _covariance_from_spec(path: object, spec: UncertaintySpec, lines: dict[tuple, int],
                          param_names: tuple[str, ...] = HEXAPOD_PARAM_NAMES,
                          is_angle: tuple[bool, ...] | None = None) -> np.ndarray:
    """The full covariance (p, p) in internal units. ``is_angle`` marks parameters whose
    ``std`` is written in degrees (the exact ``covariance`` is always internal: mm, rad)."""
    def fail(loc: tuple, message: str) -> InputFileError:
        return InputFileError(path, f"{_key_path(('uncertainty',) + loc)}: {message}",
                              line=_line_of(("uncertainty",) + loc, lines))

    names = list(spec.parameters) if spec.parameters is not None else list(spec.std)
    for i, name in enumerate(names):
        if name not in param_names:
            close = difflib.get_close_matches(name, param_names, n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            known = ("b1.x, b1.y, b1.z, a1.x, a1.y, a1.z, L0_1, ..., L0_6, gain_1, ..., gain_6"
                     if param_names is HEXAPOD_PARAM_NAMES
                     else ", ".join(param_names))
            raise fail(("parameters", i) if spec.parameters is not None else ("std", name),
                       f"unknown parameter {name!r}{hint}; the machine's parameters are {known}")
        if name in names[:i]:
            raise fail(("parameters", i), f"parameter {name!r} is listed twice")
    if set(spec.std) != set(names):
        missing = [n for n in names if n not in spec.std]
        extra = [n for n in spec.std if n not in names]
        what = (f"no standard deviation for {', '.join(missing)}" if missing
                else f"{', '.join(extra)} not in 'parameters'")
        raise fail(("std",), f"{what}; give one std per entry of 'parameters'")
    std = np.array([spec.std[n] for n in names], dtype=float)
    if is_angle is not None:
        std = np.array([np.deg2rad(s) if is_angle[param_names.index(n_)] else s for s, n_ in zip(std, names)])
    if np.any(std < 0):
        bad = names[int(np.argmax(std < 0))]
        raise fail(("std", bad), "a standard deviation cannot be negative")
    n = len(names)

    def square(key: str, rows: list[list[float]] | None) -> np.ndarray | None:
        if rows is None:
            return None
        if len(rows) != n:
            raise fail((key,), f"{len(rows)} rows, need {n} (one per parameter, in 'parameters' order)")
        for i, row in enumerate(rows):
            if len(row) != n:
                raise fail((key, i), f"{len(row)} numbers, need {n} (one per parameter)")
        return np.array(rows, dtype=float).reshape(n, n)

    full = np.zeros((len(param_names),) * 2)
    if n == 0:
        return full
    corr = square("correlation", spec.correlation)
    cov = square("covariance", spec.covariance)
    if corr is not None:
        if not np.allclose(corr, corr.T, rtol=0, atol=1e-12):
            i, j = np.unravel_index(np.argmax(np.abs(corr - corr.T)), corr.shape)
            raise fail(("correlation", int(i), int(j)), "the correlation matrix is not symmetric")
        if not np.allclose(np.diag(corr), 1.0, rtol=0, atol=1e-12) or np.any(np.abs(corr) > 1 + 1e-12):
            raise fail(("correlation",), "correlations must lie in [-1, 1] with ones on the diagonal")
    if cov is not None:
        scale = max(float(np.max(np.abs(cov))), 1e-300)
        if not np.allclose(cov, cov.T, rtol=0, atol=1e-12 * scale):
            raise fail(("covariance",), "the covariance matrix is not symmetric")
        s_cov = standard_deviations(cov)
        if np.any(np.diag(cov) < 0) or not np.allclose(s_cov, std, rtol=1e-9, atol=1e-300):
            raise fail(("std",), "disagrees with the square roots of the covariance diagonal; "
                                 "delete 'covariance' to rebuild it from std and correlation")
        if corr is not None:
            ok = np.outer(s_cov, s_cov) > 0
            if not np.allclose(correlation(cov)[ok], corr[ok], rtol=0, atol=1e-9):
                raise fail(("correlation",), "disagrees with 'covariance'; delete 'covariance' to rebuild "
                                             "it from std and correlation")
    else:
        corr = np.eye(n) if corr is None else corr
        with np.errstate(over="ignore"):      # an overflow is the clear error below, not a warning
            cov = std[:, None] * corr * std[None, :]
    scale = float(np.max(np.diag(cov))) if n else 0.0
    if n and not np.all(np.isfinite(cov)):
        raise fail(("std",), "the covariance overflows; give standard deviations in mm")
    if n and scale > 0 and np.min(np.linalg.eigvalsh((cov + cov.T) / 2)) < -1e-9 * scale:
        raise fail(("correlation",), "the covariance is not positive semi-definite; check the correlations")
    idx = np.array([param_names.index(n_) for n_ in names], dtype=int)
    full[np.ix_(idx, idx)] = cov
    return full


def _hexapod_from_file(path: object, data: dict, lines: dict[tuple, int]) -> Hexapod:
    try:
        spec = HexapodFile.model_validate(data)
    except ValidationError as exc:
        raise _validation_error(path, exc, lines) from None
    legs = spec.legs
    lim = spec.limits
    rad = lambda v: None if v is None else deg_to_rad(v)  # noqa: E731
    limits = HexapodLimits(u_joint_tilt=rad(lim.u_joint_tilt), s_joint_tilt=rad(lim.s_joint_tilt),
                           leg_diameter=lim.leg_diameter, singularity_margin=lim.singularity_margin)
    home = None
    if spec.home is not None:
        h = spec.home
        home = np.array([h.x, h.y, h.z, deg_to_rad(h.a), deg_to_rad(h.b), deg_to_rad(h.c)])
    workspace = None
    if spec.workspace is not None:
        w = spec.workspace
        workspace = np.array([list(w.x), list(w.y), list(w.z),
                              [deg_to_rad(v) for v in w.a], [deg_to_rad(v) for v in w.b],
                              [deg_to_rad(v) for v in w.c]], dtype=float)
    covariance = None if spec.uncertainty is None else _covariance_from_spec(path, spec.uncertainty, lines)
    metadata = _metadata_from_spec(spec)
    axes = lambda key: (None if all(getattr(l, key) is None for l in legs)  # noqa: E731,E741
                        else [getattr(l, key) or (0.0, 0.0, 1.0) for l in legs])
    name = spec.name if spec.name is not None else one_line(Path(str(path)).stem)
    try:
        machine = Hexapod(
            name=name,
            base=[l.base for l in legs],  # noqa: E741
            platform=[l.platform for l in legs],  # noqa: E741
            offset=[l.offset for l in legs],  # noqa: E741
            stroke=[l.stroke for l in legs],  # noqa: E741
            gains=[l.gain for l in legs],  # noqa: E741
            actuator_unit=spec.actuator_unit,
            base_axis=axes("base_axis"),
            platform_axis=axes("platform_axis"),
            limits=limits,
            home=home,
            workspace=workspace,
            covariance=covariance,
            description=spec.description,
            metadata=metadata,
        )
    except PkmcalError as exc:
        raise InputFileError(path, str(exc)) from None
    if not np.all(np.isfinite(machine.home)):
        raise InputFileError(path, "legs: the joints and offsets give no finite home pose; check the "
                                   "numbers or give 'home: {x, y, z, a, b, c}'", line=_line_of(("legs",), lines))
    return machine


def _unnormalised(axis: np.ndarray) -> list[float]:
    """A vector w with ``w / ‖w‖ == axis`` bit for bit, so the Hexapod's normalisation on load
    reproduces ``axis`` exactly (normalising a unit vector again can move it by an ulp).
    Candidates: ``axis`` scaled by 1 + k/4096 and moved by up to one ulp per component,
    normalised exactly as :class:`Hexapod` does (``norm(..., axis=1)``)."""
    axis = np.asarray(axis, dtype=float)
    steps = np.array(np.meshgrid(*[[0, -1, 1]] * 3, indexing="ij")).reshape(3, -1).T  # (27, 3), 0 first
    for lo, hi in ((0, 1), (1, 64), (64, 4096)):  # cheap candidates first
        scaled = axis[None, :] * (1.0 + np.arange(lo, hi) / 4096.0)[:, None]
        up, down = np.nextafter(scaled, np.inf), np.nextafter(scaled, -np.inf)
        cand = np.where(steps[None] == 1, up[:, None], np.where(steps[None] == -1, down[:, None], scaled[:, None]))
        cand = cand.reshape(-1, 3)
        normalised = cand / np.linalg.norm(cand, axis=1)[:, None]
        hits = np.flatnonzero(np.all(normalised == axis[None, :], axis=1))
        if len(hits):
            return [float(v) for v in cand[hits[0]]]
    return [float(v) for v in axis]


def _floats(values) -> FlowList:
    return FlowList(float(v) for v in np.asarray(values, dtype=float).ravel())


def _degs(values) -> FlowList:
    return FlowList(RawFloat(rad_to_deg_text(v)) for v in np.asarray(values, dtype=float).ravel())


def _hexapod_to_file(m: Hexapod) -> dict:
    z = np.array([0.0, 0.0, 1.0])
    out: dict[str, Any] = {"kind": "hexapod", "name": m.name}
    if m.description:
        out["description"] = m.description
    if m.actuator_unit != DEFAULT_ACTUATOR_UNIT:
        out["actuator_unit"] = m.actuator_unit
    legs = []
    for i in range(N_LEGS):
        leg: dict[str, Any] = {"base": _floats(m.base[i]), "platform": _floats(m.platform[i]),
                               "offset": float(m.offset[i]), "stroke": _floats(m.stroke[i])}
        if m.gains[i] != 1.0:
            leg["gain"] = float(m.gains[i])
        for key in ("base_axis", "platform_axis"):
            axis = getattr(m, key)[i]
            if not np.array_equal(axis, z):
                leg[key] = FlowList(_unnormalised(axis))
        legs.append(leg)
    out["legs"] = legs
    lim = m.limits
    limits: dict[str, Any] = {}
    if lim.u_joint_tilt is not None:
        limits["u_joint_tilt"] = RawFloat(rad_to_deg_text(lim.u_joint_tilt))
    if lim.s_joint_tilt is not None:
        limits["s_joint_tilt"] = RawFloat(rad_to_deg_text(lim.s_joint_tilt))
    if lim.leg_diameter is not None:
        limits["leg_diameter"] = float(lim.leg_diameter)
    limits["singularity_margin"] = float(lim.singularity_margin)
    out["limits"] = limits
    default_home = Hexapod(name=m.name, base=m.base, platform=m.platform, offset=m.offset, stroke=m.stroke,
                           gains=m.gains).home
    if not np.array_equal(m.home, default_home):
        out["home"] = {k: float(v) for k, v in zip("xyz", m.home[:3])}
        out["home"].update({k: RawFloat(rad_to_deg_text(v)) for k, v in zip("abc", m.home[3:])})
    if m.workspace is not None:
        ws = {k: _floats(m.workspace[i]) for i, k in enumerate("xyz")}
        ws.update({k: _degs(m.workspace[3 + i]) for i, k in enumerate("abc")})
        out["workspace"] = ws
    if m.covariance is not None:
        out["uncertainty"] = _uncertainty_to_file(m.covariance, HEXAPOD_PARAM_NAMES)
    out.update(_metadata_to_file(m.metadata))
    return out


def identified_uncertainty(covariance: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """What a machine file or an export states of a covariance Σ (p, p): the indices ``used``
    of the parameters with a non-zero row or column (the others were held fixed), their
    Σ_used, σ_i = √Σ_ii and ρ_ij = Σ_ij / (σ_i σ_j)
    (:func:`~pkmcal.covariance.correlation`), written exactly symmetric and
    with 1 on the diagonal (the file format's rule, also where σ = 0)."""
    cov = np.asarray(covariance, dtype=float)
    used = np.flatnonzero(np.any(cov != 0, axis=0) | np.any(cov != 0, axis=1))
    sub = cov[np.ix_(used, used)]
    corr = correlation(sub)
    corr = 0.5 * (corr + corr.T)
    np.fill_diagonal(corr, 1.0)
    return used, sub, standard_deviations(sub), corr


def _uncertainty_to_file(covariance: np.ndarray, param_names: tuple[str, ...],
                         is_angle: tuple[bool, ...] | None = None) -> dict:
    """The ``uncertainty`` block of a machine file (inverse of :func:`_covariance_from_spec`):
    :func:`identified_uncertainty` with σ in degrees where ``is_angle``, and the exact Σ in
    internal units."""
    used, sub, std, corr = identified_uncertainty(covariance)
    names = [param_names[i] for i in used]
    angle = [False] * len(used) if is_angle is None else [bool(is_angle[i]) for i in used]
    return {
        "parameters": FlowList(names),
        "std": {n: float(np.rad2deg(s)) if a else float(s) for n, s, a in zip(names, std, angle)},
        "correlation": [_floats(row) for row in corr],
        "covariance": [_floats(row) for row in sub],
    }


def _metadata_from_spec(spec: Any) -> dict:
    """A machine's metadata from its file: ``metadata:`` plus ``calibration:`` and the
    identified ``setup:`` (written by ``pkmcal identify``, read by
    :func:`pkmcal.io.setup_file.load_setup`) under those keys. The ``setup:`` mapping keeps
    its numbers' source text (:class:`~pkmcal.io._yaml.TextFloat`), so that its degree values
    are written back as read (exact round trip)."""
    metadata: dict = dict(plain(spec.metadata)) if spec.metadata else {}
    if spec.calibration is not None:
        metadata["calibration"] = plain(spec.calibration)
    if getattr(spec, "setup", None) is not None:
        metadata["setup"] = spec.setup
    return metadata


def _flow_lists(obj: Any) -> Any:
    """``obj`` with every list of scalars written on one line (:class:`FlowList`), as
    :func:`pkmcal.io.setup_file.setup_to_dict` writes them, so that a ``setup:`` mapping
    read back from a file is written again byte for byte."""
    if isinstance(obj, dict):
        return {k: _flow_lists(v) for k, v in obj.items()}
    if isinstance(obj, list):
        items = [_flow_lists(v) for v in obj]
        return FlowList(items) if all(not isinstance(v, (dict, list)) for v in items) else items
    return obj


def _metadata_to_file(metadata: dict) -> dict:
    """The ``calibration:`` and ``metadata:`` blocks of a machine file (inverse of
    :func:`_metadata_from_spec`); empty blocks are left out."""
    meta = dict(metadata)
    out: dict[str, Any] = {}
    if "calibration" in meta:
        out["calibration"] = meta.pop("calibration")
    if "setup" in meta:
        out["setup"] = _flow_lists(meta.pop("setup"))
    if meta:
        out["metadata"] = meta
    return out


@dataclass(frozen=True)
class MachineKind:
    """One machine-file kind of the registry: the ``kind:`` spellings a file may give
    (``file_kinds``, the first is the one written), the mechanism kind it builds and saves
    (:attr:`~pkmcal.mechanisms.base.Mechanism.kind`), ``read(source, data, lines)`` (the
    parsed YAML mapping → machine; ``lines`` maps key paths to line numbers, for errors;
    raises :class:`InputFileError`) and ``write(machine)`` (→ the mapping to dump, floats
    exact: :mod:`pkmcal.io._yaml`). Units are converted by the reader and writer from the
    mechanism's declared angle flags (degrees in files, radians inside)."""

    mechanism_kind: str
    file_kinds: tuple[str, ...]
    read: Callable[[object, dict, dict], Mechanism]
    write: Callable[[Any], dict]


#: The registry: ``kind:`` text of a file → its :class:`MachineKind`, in registration order
#: (the order an unknown kind's error lists them).
_KINDS: dict[str, MachineKind] = {}
#: mechanism kind → the :class:`MachineKind` that saves it (the first registered).
_WRITERS: dict[str, MachineKind] = {}
#: The ``kind:`` of a file without one.
DEFAULT_FILE_KIND = "hexapod"


# -- public API ---------------------------------------------------------------------------

def register_machine_kind(kind: str, reader: Callable[[object, dict, dict], Mechanism], cls: type,
                          writer: Callable[[Any], dict], aliases: tuple[str, ...] = ()) -> MachineKind:
    """Add the machine file ``kind`` (and its other accepted spellings ``aliases``) to the
    registry: files with ``kind: <kind>`` are read by ``reader(source, data, lines)``, and
    machines whose :attr:`~pkmcal.mechanisms.base.Mechanism.kind` is ``cls.kind`` are
    saved with ``writer(machine)`` under ``kind: <kind>`` (see :class:`MachineKind`). The
    drivers :func:`machine_from_text` and :func:`machine_to_text` need nothing else."""
    return add_machine_kind(MachineKind(mechanism_kind=cls.kind, file_kinds=(kind, *aliases), read=reader,
                                        write=writer))


def add_machine_kind(entry: MachineKind) -> MachineKind:
    """Add ``entry`` to the registry (:func:`register_machine_kind` builds it from a class)."""
    for text in entry.file_kinds:
        _KINDS[text] = entry
    _WRITERS.setdefault(entry.mechanism_kind, entry)
    return entry


def machine_kinds() -> tuple[str, ...]:
    """Every ``kind:`` a machine file may give, in registration order."""
    return tuple(_KINDS)


def machine_from_text(text: str, source: object = "<machine file>") -> Mechanism:
    """The machine described by YAML ``text``; errors name ``source`` as the file."""
    try:
        data, lines = parse_yaml(text)
    except YamlSyntaxError as exc:
        fix = "; fix the YAML syntax" if str(exc).startswith("not valid YAML") else ""
        raise InputFileError(source, f"{exc}{fix}", line=exc.line) from None
    if data is None:
        raise InputFileError(source, "the file is empty; a machine file needs at least 'name:' and 'legs:' "
                                     "(see docs/file-formats.md)")
    if not isinstance(data, dict):
        raise InputFileError(source, f"expected a mapping of 'key: value' lines (name:, legs:, ...), "
                                     f"got a {type(data).__name__}", line=lines.get(()))
    kind = data.get("kind", DEFAULT_FILE_KIND)
    if not isinstance(kind, str) or kind not in _KINDS:
        raise InputFileError(source, f"kind: {_show(kind)} is not a known machine kind; known kinds: "
                                     f"{', '.join(_KINDS)}", line=lines.get(("kind",)))
    return _KINDS[kind].read(source, data, lines)


def read_machine_file(path: str | os.PathLike) -> Mechanism:
    """The machine in the YAML file ``path``; :class:`InputFileError` when it cannot be used."""
    text = read_input_text(path, "machine file", _MAX_FILE_BYTES, "save it as UTF-8 YAML")
    machine = machine_from_text(text, path)
    record_source("machine", machine.name, os.fspath(path))
    return machine


def machine_to_text(machine: Mechanism) -> str:
    """The YAML text of ``machine`` (deterministic; exact floats; angles in degrees)."""
    entry = _WRITERS.get(machine.kind)
    if entry is None:
        raise PkmcalError(f"cannot save machine '{machine.name}': no machine file format for its kind "
                          f"'{machine.kind}' (kinds with one: {', '.join(_WRITERS)})")
    body = dump_yaml(entry.write(machine))
    return f"# pkmcal machine file (kind: {entry.file_kinds[0]}); lengths in mm, angles in degrees\n{body}"


def save_machine(machine: Mechanism, path: str | os.PathLike) -> None:
    """Write ``machine`` to the YAML file ``path`` atomically.

    Before writing, the text is loaded back and compared with ``machine`` (``==`` and the
    metadata); a machine whose file would not load (e.g. a covariance that is not positive
    semi-definite) raises :class:`PkmcalError` and nothing is written.
    """
    try:
        text = machine_to_text(machine)
    except yaml.YAMLError as exc:
        raise PkmcalError(f"cannot save machine '{machine.name}': its metadata holds a value YAML cannot "
                          f"store ({exc}); use text, numbers, lists and mappings") from None
    try:
        back = machine_from_text(text, path)
    except InputFileError as exc:
        raise PkmcalError(f"cannot save machine '{machine.name}': {exc}") from None
    if back != machine:
        raise RuntimeError(f"machine file of '{machine.name}' does not load back to the same machine")
    if back.metadata != machine.metadata:
        raise PkmcalError(f"cannot save machine '{machine.name}': its metadata does not survive YAML "
                          "unchanged; use text, numbers, lists and mappings with text keys")
    atomic_write_text(path, text)


# the Gough–Stewart hexapod (Hexapod.kind "6-UPS"): files are written "kind: hexapod", the
# spelling every pkmcal version reads; "6-UPS" is read too
register_machine_kind("hexapod", _hexapod_from_file, Hexapod, _hexapod_to_file, aliases=("6-UPS",))
for _module in MACHINE_FILE_MODULES:   # the other kinds: each module registers its own
    import_module(_module)
if PARAMETER_FILE_KINDS:               # families in the generic layout (classes imported on first read)
    from pkmcal.io.parameter_machine_file import register_parameter_kind

    for _kind, _target in PARAMETER_FILE_KINDS.items():
        register_parameter_kind(_kind, _target)

__all__ = [
    "DEFAULT_FILE_KIND",
    "HexapodFile",
    "MachineKind",
    "add_machine_kind",
    "identified_uncertainty",
    "load_machine",
    "machine_from_text",
    "machine_kinds",
    "machine_to_text",
    "read_machine_file",
    "register_machine_kind",
    "save_machine",
]
