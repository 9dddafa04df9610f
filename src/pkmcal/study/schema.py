"""Study files (YAML): which campaigns to simulate, how often, and how to judge them.

A study is a Monte Carlo experiment over simulated calibration campaigns (paper 1 §IV,
paper 2 §5): for every combination of machine × setup × pose plan × number of poses, and
for every trial, a "real" machine is drawn from the parameter-error model, the planned
poses are measured on it with the setup's noise, each method identifies the parameters
and the result is verified on held-out poses. Lengths in mm, angles in degrees (as in
every pkmcal file)::

    name: prototype-indicators            # a label for the study (results, page title)
    description: how many poses do three dial indicators need?
    seed: 0                               # same seed, same results, bit for bit
    trials: 200                           # per configuration
    machines:
      - nominal: stewart-prototype        # built-in name or machine file (relative to this file)
        label: prototype                  # optional (default: the nominal's name)
        errors:                           # parameter-error model, drawn per trial ...
          - {parameters: "b*", distribution: uniform, size: 0.5}    # U(-0.5, 0.5) mm
          - {parameters: "L0_*", distribution: normal, size: 0.2}   # N(0, 0.2²) mm
        # real: stewart-prototype-real    # ... or one real machine for every trial
        ignore_limits: [leg_collision]    # limits of the real machine not checked
        # setups: [indicators]            # optional: the setup labels it is studied with (default: all)
    setups:
      - setup: indicators-prototype       # built-in name or setup file (relative to this file)
        label: indicators                 # optional
        reading_noise_scale: 1.0          # optional multipliers of the setup's noise (reading: one, or one
        actuator_noise_scale: 1.0         # per reading, e.g. [1, 0.5]: a printed-distance setup's calipers halved)
      # - {setup: printed-distance-klipper, label: object, object_scale: 1.0, on_bed: true}   # a delta
      #     # printer's probe heights and Klipper's printed object (DELTA_ANALYZE SCALE), probed on the bed
    plans:
      - {algorithm: random, poses: [15, 30, 60, 110]}
      - {algorithm: default, poses: [15, 30, 60, 110], candidates: 2000}
    methods:
      - auto                              # the planner's default for the setup
      - {method: fk-residual, weighted: false, fix: ["b1.*", "b2.*"], label: paper-gauge}
      # - {method: auto, fix: ["target.*"], setups: [tracker]}   # only on these setups (or machines:)
    heldout: {poses: 50}                  # random reachable poses; or {file: poses.csv}
    # heldout: {poses: 50, compare: sensor}   # what is compared: auto (default), commanded, sensor, aligned

Machines of every kind (hexapods, deltas, planar redundant machines; several kinds in one
study): each setup is bound to each machine it measures (:func:`study_setup`: a planar
tracker takes the machine's pose dimension and actuator kind); a machine's ``setups:``
names the setups it is studied with, for setups that cannot measure every machine of the
study (a Z probe and a hexapod); a method's ``machines:`` and ``setups:`` the labels it fits
(a ``fix:`` list of one kind's parameter names). ``auto`` resolves per machine and setup.
A setup whose sensor reads pairs of poses (``printed-distance``: Klipper's ``DELTA_ANALYZE``)
studies a linear delta printer calibrated with probe heights and the 12 distances of
Klipper's calibration object printed at ``object_scale`` (default 1): a plan's ``poses`` are
its probe points (:mod:`pkmcal.study.printed`). ``on_bed: true`` (a Z probe, alone or with
the object) lowers the probe points onto the bed, as a printer probes; without it a probe
reads its height anywhere in the volume.

``errors`` groups match parameter names with shell patterns; every parameter matches at
most one group; unmatched parameters are exact. ``size`` is the half-width of a uniform
error and the standard deviation of a normal one (mm; degrees for angle parameters; the
parameter's own unit for the others, a hexapod's leg gains in mm per reading unit, which
only a group naming them perturbs: ``"*"`` leaves them at their values).
Plans: ``algorithm`` one of :data:`pkmcal.planning.selection.ALGORITHMS`; ``candidates``
the size of the candidate pool (drawn once per machine × setup × plan); ``resample``
``trial`` (a new selection from the pool in every trial; the default for ``random`` and
``corners``) or ``once`` (one selection used in every trial; the default for the
optimising planners, as an engineer plans once and measures). ``margin`` and ``index`` as
for ``pkmcal plan`` (no ``margin``: the safety margins a real machine survives,
:func:`pkmcal.planning.margins.default_margin`; a number: that margin on every limit).

:func:`load_study` validates a file with pydantic and resolves it into a :class:`Study`
(machines and setups loaded); errors name the file, line and key. The schema is strict: a
number is a number (``trials: true`` and ``trials: "10"`` are errors, not 1 and 10), a flag is
``true`` or ``false``; lengths, angles and factors beyond
:data:`~pkmcal.io.limits.MAX_MAGNITUDE` are refused; every name or pattern of a method's
``free:``/``fix:`` must name a parameter of each machine and setup the method fits (a typo
would fail every one of its trials), the message giving the closest names.
"""

from __future__ import annotations

import difflib
import fnmatch
import hashlib
import json
import os
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Literal, Union, get_args

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from pkmcal.errors import InputFileError, PkmcalError
from pkmcal.identification.residuals import METHODS as ENGINE_METHODS, pattern_matches
from pkmcal.identification.baselines import BASELINES
from pkmcal.io._yaml import YamlSyntaxError, parse_yaml
from pkmcal.io.inputs import read_input_text
from pkmcal.io.limits import MAX_MAGNITUDE, magnitude_problem
from pkmcal.io.machine_file import load_machine, machine_to_text
from pkmcal.io.setup_file import describe_error, load_setup, setup_to_yaml
from pkmcal.mechanisms.base import Mechanism
from pkmcal.planning.blocks import default_method
from pkmcal.planning.selection import ALGORITHMS
from pkmcal.sensors.base import MeasurementSetup, NoiseModel

#: Plans whose selection is cheap and random: re-drawn in every trial by default.
RESAMPLED_BY_DEFAULT = ("random", "corners")
#: Largest accepted number of trials per configuration and of poses per plan.
MAX_TRIALS = 10_000_000
MAX_POSES = 100_000


class _Strict(BaseModel):
    # strict: a number is a number (true is not 1, "10" is not 10), a flag is true or false
    model_config = ConfigDict(extra="forbid", strict=True)


def _plausible(v):
    """A length or angle (mm, degrees) within :data:`~pkmcal.io.limits.MAX_MAGNITUDE`: an
    error size of 1e308 is a wrong number, and overflowed the random draws."""
    if v is not None and (problem := magnitude_problem(v, None)) is not None:
        raise ValueError(problem)
    return v


def _factor(v):
    """A factor (or each of a list) of at most :data:`~pkmcal.io.limits.MAX_MAGNITUDE`."""
    for x in v if isinstance(v, list) else [v]:
        if x is not None and not abs(x) <= MAX_MAGNITUDE:
            raise ValueError(f"{x!r} is not a plausible factor (at most {MAX_MAGNITUDE:g}); check the number")
    return v


class _ErrorGroup(_Strict):
    parameters: str
    distribution: Literal["uniform", "normal"]
    size: float = Field(ge=0.0, allow_inf_nan=False)

    _size = field_validator("size")(_plausible)


class _Machine(_Strict):
    nominal: str
    label: str | None = None
    errors: list[_ErrorGroup] | None = None
    real: str | None = None
    ignore_limits: list[str] = []
    setups: list[str] | None = None


class _Setup(_Strict):
    setup: str
    label: str | None = None
    reading_noise_scale: Union[float, list[float]] = 1.0
    actuator_noise_scale: float = Field(1.0, ge=0.0, allow_inf_nan=False)
    object_scale: float | None = Field(None, gt=0.0, allow_inf_nan=False)
    on_bed: bool = False

    @field_validator("reading_noise_scale")
    @classmethod
    def _factors(cls, v):
        values = v if isinstance(v, list) else [v]
        if not values or not all(np.isfinite(x) and x >= 0 for x in values):
            raise ValueError("give one finite factor ≥ 0, or one per reading of the setup")
        return _factor(v)

    _scales = field_validator("actuator_noise_scale", "object_scale")(_factor)


class _Plan(_Strict):
    algorithm: str
    poses: list[int]
    candidates: int = Field(2000, ge=1, le=10_000_000)
    resample: Literal["trial", "once"] | None = None
    margin: float | None = Field(None, ge=0.0, allow_inf_nan=False)
    index: Literal["O1", "O2", "O3", "O4", "O5"] | None = None
    label: str | None = None

    _margin = field_validator("margin")(_plausible)

    @field_validator("algorithm")
    @classmethod
    def _known(cls, v: str) -> str:
        if v.lower() not in ALGORITHMS:
            raise ValueError(f"unknown algorithm '{v}'; use one of {', '.join(ALGORITHMS)}")
        return v.lower()

    @field_validator("poses")
    @classmethod
    def _counts(cls, v: list[int]) -> list[int]:
        if not v or any(n < 1 or n > MAX_POSES for n in v) or len(set(v)) != len(v):
            raise ValueError(f"give a non-empty list of distinct pose counts between 1 and {MAX_POSES}")
        return v


class _Method(_Strict):
    method: str
    weighted: bool = True
    free: list[str] | None = None
    fix: list[str] | Literal["auto"] | None = None
    label: str | None = None
    machines: list[str] | None = None
    setups: list[str] | None = None

    @field_validator("method")
    @classmethod
    def _known(cls, v: str) -> str:
        if v != "auto" and v not in METHODS:
            raise ValueError(f"unknown method '{v}'; use auto or one of {', '.join(METHODS)}")
        return v


#: Methods a study fits with: the engine's, and paper 3's baselines for redundantly actuated
#: machines (``ignore-redundancy``, ``actuator-subset``: the engine's projection fit on the
#: inputs they change, as ``pkmcal identify --method``).
METHODS = ENGINE_METHODS + BASELINES

#: What the held-out errors compare (``heldout: {compare: ...}``): ``auto`` chooses per
#: configuration (:func:`pkmcal.study.trial.heldout_compare`), ``commanded`` the platform
#: poses as commanded (the papers' figures), ``sensor`` what the instrument reads,
#: ``aligned`` the platform poses after the best rigid alignment of each model's frames.
HELDOUT_COMPARES = Literal["auto", "commanded", "sensor", "aligned"]


class _HeldOut(_Strict):
    poses: int | None = Field(None, ge=1, le=MAX_POSES)
    file: str | None = None
    compare: HELDOUT_COMPARES = "auto"


class _Study(_Strict):
    name: str
    description: str = ""
    seed: int = Field(0, ge=0)
    trials: int = Field(ge=1, le=MAX_TRIALS)
    machines: list[_Machine] = Field(min_length=1)
    setups: list[_Setup] = Field(min_length=1)
    plans: list[_Plan] = Field(min_length=1)
    methods: list[Union[str, _Method]] = Field(default_factory=lambda: ["auto"], min_length=1)
    heldout: _HeldOut = _HeldOut(poses=50)


# -- the resolved study ------------------------------------------------------------------


@dataclass(frozen=True)
class ErrorGroup:
    """Parameters matching ``pattern`` get an error U(−size, size) (``uniform``) or
    N(0, size²) (``normal``); ``size`` in internal units (mm, rad)."""

    pattern: str
    distribution: str
    size: float


@dataclass(frozen=True)
class MachineSpec:
    """A nominal machine and how its real counterpart is made: one fixed ``real`` machine,
    or random ``errors`` per trial (``real`` None)."""

    label: str
    nominal: Mechanism
    real: Mechanism | None = None
    errors: tuple[ErrorGroup, ...] = ()
    ignore_limits: tuple[str, ...] = ()

    def error_index(self) -> list[np.ndarray]:
        """Per error group, the indices of the parameters it perturbs. A group that matches
        parameters in mm or degrees leaves those in other units (a hexapod's leg gains, mm
        per reading unit) exact: ``"*"`` means the geometry; name them (``gain_*``) to
        perturb them."""
        unitless = ~np.isin(self.nominal.param_units, ("mm", "deg"))
        out = []
        for g in self.errors:
            hit = np.array([fnmatch.fnmatchcase(n, g.pattern) for n in self.nominal.param_names], dtype=bool)
            if np.any(hit & ~unitless):
                hit &= ~unitless
            out.append(np.flatnonzero(hit).astype(int))
        return out

    def describe(self) -> str:
        if self.real is not None:
            return f"real machine '{self.real.name}' in every trial"
        parts = [f"{g.pattern}: {'U(±' if g.distribution == 'uniform' else 'N(0, '}{g.size:g}"
                 f"{')' if g.distribution == 'uniform' else '²)'}" for g in self.errors]
        return "random errors per trial (mm, rad): " + ", ".join(parts)


@dataclass(frozen=True)
class SetupSpec:
    """A measurement setup. ``bound``: per study machine, the setup bound to that machine
    (:func:`study_setup`; a planar tracker takes the machine's pose dimension and actuator
    kind), None where the machine is not studied with it (its ``setups:`` list); empty: the
    setup as given for every machine (bound when the study is prepared). ``setup`` is the
    setup as given, or bound to the first machine that uses it."""

    label: str
    setup: MeasurementSetup
    bound: tuple[MeasurementSetup | None, ...] = ()
    #: the scale of Klipper's calibration object a setup of pose pairs measures (its
    #: ``DELTA_ANALYZE SCALE``; :mod:`pkmcal.study.printed`)
    object_scale: float = 1.0
    #: a Z probe's probe points lowered onto the bed, as a printer probes (:mod:`pkmcal.study.printed`)
    on_bed: bool = False

    def for_machine(self, machine: int, nominal: Mechanism) -> MeasurementSetup | None:
        """The setup machine ``machine`` (index, its nominal ``nominal``) is studied with,
        or None."""
        if self.bound:
            return self.bound[machine]
        return study_setup(self.setup, nominal, f"study setup '{self.label}'")


@dataclass(frozen=True)
class PlanSpec:
    """A pose planner and the pose counts to study; ``resample`` "trial" or "once"."""

    label: str
    algorithm: str
    poses: tuple[int, ...]
    candidates: int = 2000
    resample: str = "trial"
    margin: float | None = None
    index: str | None = None


@dataclass(frozen=True)
class MethodSpec:
    """An identification method with its options (``method`` "auto": the planner's
    default for the setup, :func:`pkmcal.planning.blocks.default_method`)."""

    label: str
    method: str
    weighted: bool = True
    free: tuple[str, ...] | None = None
    fix: tuple[str, ...] | str | None = None
    #: the labels of the machines / setups it fits (None: all), e.g. a ``fix:`` list of one
    #: kind's parameter names in a study of several kinds
    machines: tuple[str, ...] | None = None
    setups: tuple[str, ...] | None = None

    def fits(self, machine: str, setup: str) -> bool:
        """Whether it fits the campaigns of machine and setup labels ``machine``, ``setup``."""
        return (self.machines is None or machine in self.machines) and (self.setups is None or setup in self.setups)

    def resolved(self, setup: MeasurementSetup, machine: Mechanism) -> str:
        return default_method(setup, machine) if self.method == "auto" else self.method


#: Extra per-trial metrics of a reproduction: ``f(nominal, real, setup, sim, fit, heldout)``
#: → {column: float}; a module-level function (workers receive it by reference).
ExtraMetrics = Callable[..., dict]


@dataclass(frozen=True)
class Study:
    """A validated, resolved study (:func:`load_study`, or built in Python)."""

    name: str
    trials: int
    machines: tuple[MachineSpec, ...]
    setups: tuple[SetupSpec, ...]
    plans: tuple[PlanSpec, ...]
    methods: tuple[MethodSpec, ...]
    heldout_poses: int | None = 50
    heldout_file: np.ndarray | None = None
    #: what the held-out errors compare (:data:`HELDOUT_COMPARES`, :func:`pkmcal.study.trial.heldout_compare`)
    heldout_compare: str = "auto"
    seed: int = 0
    description: str = ""
    source: str = ""
    extra_metrics: ExtraMetrics | None = None
    extra_columns: tuple[str, ...] = ()

    def __post_init__(self):
        _unique("machine", [m.label for m in self.machines])
        _unique("setup", [s.label for s in self.setups])
        _unique("plan", [p.label for p in self.plans])
        _unique("method", [m.label for m in self.methods])
        for s in self.setups:
            if s.bound and len(s.bound) != len(self.machines):
                raise PkmcalError(f"study setup '{s.label}' is bound to {len(s.bound)} machines; the study has "
                                  f"{len(self.machines)}")
        for i, m in enumerate(self.machines):
            if all(s.bound and s.bound[i] is None for s in self.setups):
                raise PkmcalError(f"study machine '{m.label}' is studied with none of the setups")
            for j, s in enumerate(self.setups):
                if (not s.bound or s.bound[i] is not None) and not self.methods_for(i, j):
                    raise PkmcalError(f"no method fits machine '{m.label}' with setup '{s.label}' (the methods' "
                                      "'machines:' and 'setups:' lists); add one, or leave the setup out of the "
                                      "machine's 'setups:'")
        from pkmcal.identification.simulation import settles_at_equilibrium

        for me in self.methods:
            if me.method not in BASELINES:
                continue
            for m in self.machines:
                if any(me.fits(m.label, s.label) for s in self.setups) and not settles_at_equilibrium(m.nominal):
                    raise PkmcalError(f"method '{me.label}' ({me.method}) is a paper 3 baseline for redundantly "
                                      f"actuated machines; machine '{m.label}' is not one: restrict the method "
                                      "with 'machines: [...]'")
        if self.heldout_compare not in get_args(HELDOUT_COMPARES):
            raise PkmcalError(f"heldout compare '{self.heldout_compare}': use one of {', '.join(get_args(HELDOUT_COMPARES))}")
        if self.heldout_compare != "auto":
            for m in self.machines:
                if settles_at_equilibrium(m.nominal):
                    raise PkmcalError(f"heldout compare '{self.heldout_compare}': machine '{m.label}' settles at static "
                                      "equilibrium and is verified on what its tracker reads; leave 'compare' out")
        if self.heldout_file is not None:
            kinds = {m.nominal.pose_names for m in self.machines}
            if len(kinds) > 1:
                raise PkmcalError("a held-out pose file gives the poses of one kind of machine; these machines have "
                                  f"poses {' and '.join('(' + ', '.join(k) + ')' for k in sorted(kinds))}: use "
                                  "heldout: {poses: N} (random reachable poses of each machine)")

    @property
    def reads_pose_pairs(self) -> bool:
        """True when a setup reads pairs of poses (a printed object with probe heights,
        :mod:`pkmcal.study.printed`): the trials then also say whether the scale is
        determined (:data:`~pkmcal.study.results.SCALE_COLUMNS`)."""
        return any(b is not None and b.sensor.reads_pose_pairs for s in self.setups for b in (s.bound or (s.setup,)))

    def methods_for(self, machine: int, setup: int) -> tuple[int, ...]:
        """Indices of the methods that fit machine ``machine`` with setup ``setup``."""
        m, s = self.machines[machine].label, self.setups[setup].label
        return tuple(k for k, me in enumerate(self.methods) if me.fits(m, s))

    def setup_for(self, machine: int, setup: int) -> MeasurementSetup | None:
        """Setup ``setup`` bound to machine ``machine`` (indices), or None where that machine
        is not studied with it."""
        return self.setups[setup].for_machine(machine, self.machines[machine].nominal)

    def with_seed(self, seed: int) -> "Study":
        return replace(self, seed=int(seed))

    def with_trials(self, trials: int) -> "Study":
        return replace(self, trials=int(trials))

    def fingerprint(self) -> str:
        """A hash of everything the results depend on except the number of trials (so
        that ``--resume`` can extend a study): machines and setups as their file texts,
        plans, methods, held-out set, seed, extra metrics and the pkmcal version."""
        from pkmcal import __version__

        doc = {
            "version": __version__, "seed": self.seed,
            "machines": [[m.label, machine_to_text(m.nominal), None if m.real is None else machine_to_text(m.real),
                          [[g.pattern, g.distribution, repr(g.size)] for g in m.errors], list(m.ignore_limits)]
                         for m in self.machines],
            "setups": [[s.label, setup_to_yaml(s.setup)] for s in self.setups],
            **self._bound_fingerprint(),
            "plans": [[p.label, p.algorithm, list(p.poses), p.candidates, p.resample, repr(p.margin), p.index]
                      for p in self.plans],
            "methods": [[m.label, m.method, m.weighted, m.free and list(m.free),
                         m.fix if isinstance(m.fix, (str, type(None))) else list(m.fix)]
                        + ([] if m.machines is None and m.setups is None else
                           [m.machines and list(m.machines), m.setups and list(m.setups)]) for m in self.methods],
            "heldout": [self.heldout_poses, None if self.heldout_file is None else self.heldout_file.tobytes().hex(),
                        self.heldout_compare],
            "extra": None if self.extra_metrics is None else
            f"{self.extra_metrics.__module__}.{self.extra_metrics.__qualname__}",
        }
        if self.reads_pose_pairs or any(s.on_bed for s in self.setups):   # only then: the others keep theirs
            doc["printer"] = [[s.label, repr(s.object_scale), s.on_bed] for s in self.setups]
        return hashlib.sha256(json.dumps(doc, sort_keys=True).encode()).hexdigest()

    def _bound_fingerprint(self) -> dict:
        """``{"bound_setups": ...}`` when a setup is bound to a machine otherwise than as
        given (another pose dimension, actuator kind, or not used by it), else ``{}`` (so
        that the studies of one kind of machine keep their fingerprints)."""
        texts = [[None if b is None else setup_to_yaml(b) for b in s.bound] for s in self.setups]
        if all(t == setup_to_yaml(s.setup) for s, ts in zip(self.setups, texts) for t in ts):
            return {}
        return {"bound_setups": [[s.label, ts] for s, ts in zip(self.setups, texts)]}


def _unique(what: str, labels: list[str]) -> None:
    seen = {x for x in labels if labels.count(x) > 1}
    if seen:
        raise PkmcalError(f"two {what}s have the label '{sorted(seen)[0]}'; give each a distinct 'label:'")


def study_setup(setup: MeasurementSetup, machine: Mechanism, source: str) -> MeasurementSetup:
    """``setup`` bound to ``machine`` (:func:`pkmcal.sensors.library.bind_setup`: a planar
    tracker takes the machine's pose dimension); a :class:`PkmcalError` naming ``source``
    when its sensor cannot measure the machine, or when the machine settles at static
    equilibrium (redundantly actuated, paper 3) and the setup has no ``simulation:``
    stiffness and load to simulate and verify it with."""
    from pkmcal.identification.simulation import settles_at_equilibrium
    from pkmcal.sensors.library import bind_setup

    if setup.sensor.reads_pose_pairs:
        from pkmcal.mechanisms.pose_pairs import PosePairs
        from pkmcal.study.printed import PRINTER_KINDS

        if machine.kind not in PRINTER_KINDS:
            raise PkmcalError(f"{source}: a '{setup.sensor.kind}' sensor reads the distances of Klipper's calibration "
                              "object (DELTA_ANALYZE) with the probe heights of a linear delta printer; machine "
                              f"'{machine.name}' is a {machine.kind}: study it with a setup of single poses "
                              "(z-probe-klipper, laser-tracker)")
        return bind_setup(setup, PosePairs(machine), source)
    bound = bind_setup(setup, machine, source)
    if settles_at_equilibrium(machine) and bound.simulation is None:
        raise PkmcalError(f"{source}: machine '{machine.name}' is redundantly actuated and settles at static "
                          "equilibrium; give the setup a 'simulation:' block with the actuator stiffness and the tool "
                          "load (e.g. the built-in planar-tracker)")
    return bound


def scaled_noise(setup: MeasurementSetup, reading, actuator: float) -> MeasurementSetup:
    """``setup`` with its reading and actuator noise multiplied by the given factors
    (``reading``: one factor, or one per reading, e.g. a printed-distance setup's probe and
    calipers)."""
    if np.all(np.asarray(reading) == 1.0) and actuator == 1.0:
        return setup
    reading = np.asarray(reading, dtype=float)
    if reading.ndim and reading.size != setup.sensor.n_readings:
        raise PkmcalError(f"{reading.size} reading noise factors for the {setup.sensor.n_readings} readings "
                          f"({', '.join(setup.sensor.reading_names)}) of a '{setup.sensor.kind}' sensor; give one "
                          "factor, or one per reading")
    n = setup.noise
    noise = NoiseModel(np.asarray(n.reading_std, float) * reading, np.asarray(n.actuator_std, float) * actuator,
                       n.distribution)
    return replace(setup, noise=noise)


# -- loading -----------------------------------------------------------------------------


def _file_loc(loc: tuple) -> tuple:
    """A pydantic error location without the names of union branches (``str``, ``list[float]``)."""
    return tuple(p for p in loc if not (isinstance(p, str) and ("[" in p or p in ("str", "int", "float", "_Method"))))


def _key_text(loc: tuple) -> str:
    text = ""
    for p in _file_loc(loc):
        text += f"[{p}]" if isinstance(p, int) else (f".{p}" if text else str(p))
    return text or "(top level)"


def _line(lines: dict[tuple, int], loc: tuple) -> int | None:
    best, path = lines.get(()), ()
    for part in loc:
        if path + (part,) in lines:
            path = path + (part,)
            best = lines[path]
    return best


def _resolve(base: Path, name: str) -> str:
    """A path relative to the study file's folder when that file exists, else ``name``
    unchanged (a built-in machine or setup name)."""
    p = Path(name)
    candidate = p if p.is_absolute() else base / p
    return str(candidate) if candidate.exists() else name


def load_study(path: str | os.PathLike) -> Study:
    """The study of a YAML file (module docstring), validated and resolved.

    Raises :class:`~pkmcal.errors.InputFileError` naming the file, the line and the key.
    """
    p = Path(path)
    text = read_input_text(p, "study file", fix="save it as UTF-8 YAML")
    try:
        data, lines = parse_yaml(text)
    except YamlSyntaxError as exc:
        raise InputFileError(path, str(exc), line=exc.line) from None
    if not isinstance(data, dict):
        raise InputFileError(path, "a study file is a YAML mapping with name, trials, machines, setups and plans")
    try:
        spec = _Study.model_validate(data)
    except ValidationError as exc:
        errs = exc.errors()
        err = next((e for e in errs if e["type"] == "extra_forbidden"), errs[0])
        # a value of a union (methods: a name or a mapping; one factor or a list): the branch
        # that got furthest into it says what is wrong
        first = _file_loc(err["loc"])
        err = max((e for e in errs if _file_loc(e["loc"])[:len(first)] == first), key=lambda e: len(_file_loc(e["loc"])))
        loc = tuple(err["loc"])
        if err["type"] == "extra_forbidden":
            msg = "is not a study key here; remove or correct it"
        elif err["type"] == "missing":
            msg = "is missing"
        else:
            msg = describe_error(err)
        raise InputFileError(path, f"key '{_key_text(loc)}': {msg}", line=_line(lines, loc)) from None
    return _build(p, spec, lines, text)


def _bound_setup(name: str, machine: Mechanism, source: str) -> MeasurementSetup:
    """The setup file or built-in ``name`` bound to ``machine`` (:func:`study_setup`): read as
    written, or, for a built-in made for its machine (``planar-tracker`` takes the
    machine's actuator kind), made for ``machine``."""
    try:
        setup = load_setup(name)
    except PkmcalError:
        setup = load_setup(name, machine)     # raises the file's own error again, if it has one
    return study_setup(setup, machine, source)


def _by_unit(machine: Mechanism, names: list[str]) -> str:
    """``names`` (parameters of ``machine``) grouped by unit: "a, b (mm); c (deg)"."""
    unit = dict(zip(machine.param_names, machine.param_units))
    groups: dict[str, list[str]] = {}
    for n in names:
        groups.setdefault(unit[n], []).append(n)
    return "; ".join(f"{', '.join(v)} ({u})" for u, v in groups.items())


def _machine_setups(path, lines, spec: _Study, machines: list, labels: list[str]) -> list[list[bool]]:
    """Per machine, per setup: whether the machine is studied with it (its ``setups:``
    list of setup labels; every setup when it has none)."""
    out = []
    for k, m in enumerate(spec.machines):
        if m.setups is None:
            out.append([True] * len(labels))
            continue
        for j, name in enumerate(m.setups):
            if name not in labels:
                _fail(path, lines, ("machines", k, "setups", j), f"'{name}' is not the label of a study setup "
                      f"({', '.join(labels)})")
        if not m.setups:
            _fail(path, lines, ("machines", k, "setups"), f"machine '{machines[k].label}' needs at least one setup")
        out.append([lab in m.setups for lab in labels])
    return out


def _object_scale(path, lines, i: int, given: _Setup, setup: MeasurementSetup, machines: list) -> float:
    """The ``object_scale`` of study setup ``i`` (1 unless given): only for a setup that reads a
    printed object, whose every machine must be able to print it."""
    if not setup.sensor.reads_pose_pairs:
        if given.object_scale is not None:
            _fail(path, lines, ("setups", i, "object_scale"), f"is the scale of a printed calibration object; setup "
                  f"'{given.setup}' has a '{setup.sensor.kind}' sensor (use a 'printed-distance' setup, e.g. "
                  "printed-distance-klipper)")
        return 1.0
    from pkmcal.study.printed import object_poses

    scale = 1.0 if given.object_scale is None else given.object_scale
    for m in machines:
        try:
            object_poses(m.nominal, scale)
        except PkmcalError as exc:
            _fail(path, lines, ("setups", i, "object_scale" if given.object_scale is not None else "setup"), str(exc))
    return scale


def _check_parameter_names(path, lines, machines: list[MachineSpec], setups: list[SetupSpec],
                           methods: list[MethodSpec]) -> None:
    """Every name or pattern of a method's ``free:`` and ``fix:`` lists names a parameter of each
    machine and setup it fits (as the engine matches them,
    :func:`~pkmcal.identification.residuals.pattern_matches`); a misspelt one made every
    trial of those configurations fail."""
    for i, me in enumerate(methods):
        for key, patterns in (("free", me.free), ("fix", me.fix)):
            if patterns is None or isinstance(patterns, str):
                continue
            for j, pat in enumerate(patterns):
                for k, m in enumerate(machines):
                    for sp in setups:
                        bound = sp.bound[k] if sp.bound else sp.setup
                        if bound is None or not me.fits(m.label, sp.label):
                            continue
                        names = tuple(m.nominal.param_names) + tuple(bound.sensor.param_names)
                        if pattern_matches(names, pat):
                            continue
                        close = difflib.get_close_matches(pat, names, n=3)
                        hint = (f"did you mean {' or '.join(repr(c) for c in close)}?" if close else
                                f"the parameters are {', '.join(names)}")
                        _fail(path, lines, ("methods", i, key, j), f"'{pat}' names no parameter of machine "
                              f"'{m.label}' with setup '{sp.label}', so every trial of method '{me.label}' would "
                              f"fail; {hint}")


def _fail(path, lines, loc: tuple, message: str):
    raise InputFileError(path, f"key '{_key_text(loc)}': {message}", line=_line(lines, loc))


def _build(path: Path, spec: _Study, lines: dict, text: str) -> Study:
    from pkmcal.sensors.printed_distance import single_pose_setup
    from pkmcal.study.printed import probes_the_bed

    base = path.parent

    def load(loc, fn, name):
        try:
            return fn(_resolve(base, name))
        except PkmcalError as exc:
            _fail(path, lines, loc, str(exc))

    machines = []
    for i, m in enumerate(spec.machines):
        loc = ("machines", i)
        nominal = load(loc + ("nominal",), load_machine, m.nominal)
        if (m.errors is None) == (m.real is None):
            _fail(path, lines, loc, "give exactly one of 'errors' (random errors per trial) or 'real' (one real machine)")
        real = None if m.real is None else load(loc + ("real",), load_machine, m.real)
        groups = []
        if m.errors is not None:
            names = nominal.param_names
            owner: dict[str, int] = {}
            for k, g in enumerate(m.errors):
                hit = [n for n in names if fnmatch.fnmatchcase(n, g.parameters)]
                if not hit:
                    _fail(path, lines, loc + ("errors", k, "parameters"),
                          f"'{g.parameters}' matches no parameter of '{nominal.name}'; its parameters: "
                          f"{_by_unit(nominal, names)}")
                for n in hit:
                    if n in owner:
                        _fail(path, lines, loc + ("errors", k, "parameters"),
                              f"parameter '{n}' is already in group {owner[n] + 1}; each parameter in at most one group")
                    owner[n] = k
                angle = [nominal.param_is_angle[names.index(n)] for n in hit]
                if any(angle) and not all(angle):
                    _fail(path, lines, loc + ("errors", k, "parameters"),
                          f"'{g.parameters}' mixes length and angle parameters of '{nominal.name}' "
                          f"({_by_unit(nominal, hit)}); a group's size has one unit: give them separate groups "
                          "(size in mm for lengths, degrees for angles), e.g. one pattern per name family")
                size = float(np.deg2rad(g.size)) if all(angle) else float(g.size)
                groups.append(ErrorGroup(g.parameters, g.distribution, size))
        limits = tuple(m.ignore_limits)
        known = tuple(nominal.check_limits(nominal.home_pose[None, :]).violations)
        bad = [n for n in limits if n not in known]
        if bad:
            _fail(path, lines, loc + ("ignore_limits",), f"'{bad[0]}' is not a limit of '{nominal.name}' "
                  f"({', '.join(known)})")
        machines.append(MachineSpec(m.label or nominal.name, nominal, real, tuple(groups), limits))

    setups = []
    labels = [s.label or Path(s.setup).stem for s in spec.setups]
    uses = _machine_setups(path, lines, spec, machines, labels)
    for i, s in enumerate(spec.setups):
        bound: list[MeasurementSetup | None] = []
        for k, m in enumerate(machines):
            if not uses[k][i]:
                bound.append(None)
                continue
            try:
                setup = _bound_setup(_resolve(base, s.setup), m.nominal, f"setup '{s.setup}'")
            except PkmcalError as exc:
                if len(machines) == 1 or isinstance(exc, InputFileError):
                    _fail(path, lines, ("setups", i, "setup"), str(exc))
                _fail(path, lines, ("setups", i, "setup"), f"machine '{m.label}': {exc}; list the setups each "
                      "machine is studied with in its entry (machines[N].setups: [setup labels])")
            try:
                bound.append(scaled_noise(setup, s.reading_noise_scale, s.actuator_noise_scale))
            except PkmcalError as exc:
                _fail(path, lines, ("setups", i, "reading_noise_scale"), str(exc))
        first = next((b for b in bound if b is not None), None)
        if first is None:
            _fail(path, lines, ("setups", i), f"setup '{labels[i]}' is used by no machine (their 'setups:' lists); "
                  "remove it or name it in a machine's 'setups:'")
        scale = _object_scale(path, lines, i, s, first, [m for m, b in zip(machines, bound) if b is not None])
        if s.on_bed and not probes_the_bed(single_pose_setup(first).sensor):
            _fail(path, lines, ("setups", i, "on_bed"), f"lowers a Z probe's probe points onto the bed; setup "
                  f"'{s.setup}' has a '{first.sensor.kind}' sensor, which reads where the machine is sent")
        setups.append(SetupSpec(labels[i], first, tuple(bound), scale, s.on_bed))

    plans = []
    for i, pl in enumerate(spec.plans):
        resample = pl.resample or ("trial" if pl.algorithm in RESAMPLED_BY_DEFAULT else "once")
        plans.append(PlanSpec(pl.label or pl.algorithm, pl.algorithm, tuple(pl.poses), pl.candidates, resample,
                              pl.margin, pl.index))

    methods = []
    for i, me in enumerate(spec.methods):
        if isinstance(me, str):
            if me != "auto" and me not in METHODS:
                _fail(path, lines, ("methods", i), f"unknown method '{me}'; use auto or one of {', '.join(METHODS)}")
            me = _Method(method=me)
        fix = me.fix if isinstance(me.fix, (str, type(None))) else tuple(me.fix)
        for key, given, known in (("machines", me.machines, [m.label for m in machines]),
                                  ("setups", me.setups, [s.label for s in setups])):
            for j, name in enumerate(given or ()):
                if name not in known:
                    _fail(path, lines, ("methods", i, key, j), f"'{name}' is not the label of a study "
                          f"{key[:-1]} ({', '.join(known)})")
            if given is not None and not given:
                _fail(path, lines, ("methods", i, key), f"name at least one {key[:-1]}, or leave '{key}' out")
        methods.append(MethodSpec(me.label or me.method, me.method, me.weighted,
                                  None if me.free is None else tuple(me.free), fix,
                                  None if me.machines is None else tuple(me.machines),
                                  None if me.setups is None else tuple(me.setups)))

    _check_parameter_names(path, lines, machines, setups, methods)

    h = spec.heldout
    if (h.poses is None) == (h.file is None):
        _fail(path, lines, ("heldout",), "give exactly one of 'poses' (random reachable poses) or 'file' (a pose CSV)")
    held = None
    if h.file is not None:
        from pkmcal.io.tables import read_poses

        held = load(("heldout", "file"), lambda f: read_poses(f, machines[0].nominal), h.file)
    try:
        return Study(name=spec.name, trials=spec.trials, machines=tuple(machines), setups=tuple(setups),
                     plans=tuple(plans), methods=tuple(methods), heldout_poses=h.poses, heldout_file=held,
                     heldout_compare=h.compare, seed=spec.seed, description=spec.description, source=text)
    except PkmcalError as exc:
        raise InputFileError(path, str(exc)) from None


__all__ = ["ErrorGroup", "MachineSpec", "MethodSpec", "PlanSpec", "SetupSpec", "Study", "load_study", "scaled_noise"]
