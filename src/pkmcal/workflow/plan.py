"""Which poses to measure, and how good a set is, from files (``pkmcal plan``, ``pkmcal
observability``; the Python API's :func:`pkmcal.plan` works on objects).

* :func:`plan_inputs`: the nominal machine and setup, and the safety margins a real machine
  survives (:mod:`pkmcal.planning.margins`), checked against what the setup is (a Z probe's
  options);
* :func:`plan_of`: candidate poses (random in the workspace box, a grid, or a CSV) checked
  against the nominal machine's limits with those margins and the sensor's measurability,
  then a selection algorithm (:mod:`pkmcal.planning.selection`, paper 2 §4, paper 1 §IV)
  picks N of them → :class:`PosePlan` (its CSV, a Z probe's printer file, its summary with the
  predicted first-layer error, :func:`pkmcal.planning.plan.height_sigma`);
* :func:`iso9283_plan`: the ISO 9283 test pattern instead of a selection
  (:func:`pkmcal.identification.iso9283.iso9283_pattern`) → :class:`PatternPlan`;
* :func:`observability_of`: the indices O1..O5 (:mod:`pkmcal.planning.indices`) of a pose set,
  on the same identifiable parameters and column scaling as the plan.
"""

from __future__ import annotations

import contextlib
import dataclasses
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from pkmcal.errors import PkmcalError
from pkmcal.planning.plan import Plan

#: What ``plan --format`` writes: the poses, a Klipper macro, Marlin G-code (Z probes).
PLAN_FORMATS = ("csv", "klipper", "gcode")


def measurability(travel=None, plate_radius=None, sight_cone=None):
    """The :class:`~pkmcal.planning.candidates.Measurability` of the options: an indicator's
    accepted reading range (lo, hi) mm, the touch points' plate radius (mm), the target's
    line-of-sight half-angle (degrees)."""
    from pkmcal.planning.candidates import Measurability

    return Measurability(travel=None if travel is None else (float(travel[0]), float(travel[1])),
                         plate_radius=plate_radius,
                         sight_cone=None if sight_cone is None else float(np.deg2rad(sight_cone)))


def format_indices(ind: dict[str, float]) -> str:
    """O1..O5 on one line (the plan's summary and its CSV's comment)."""
    from pkmcal.planning.indices import INDEX_NAMES

    return "  ".join(f"{k} = {ind[k]:.6g}" for k in INDEX_NAMES)


def _number(v) -> float | None:
    """A float for JSON: None where not finite (an index of a degenerate pose set)."""
    return float(v) if np.isfinite(v) else None


def plan_inputs(machine, setup, *, probe_anywhere: bool = False, target_accuracy: float | None = None,
                fmt: str = "csv", units_comment: bool = False, stroke_margin: float | None = None,
                tilt_margin: float | None = None, clearance_margin: float | None = None,
                margin: float | None = None) -> tuple:
    """``(nominal, setup, safety margin)`` of ``pkmcal plan MACHINE --setup SETUP``: ``machine``
    and ``setup`` files or built-in names; the Z probe's options refused for another sensor;
    the margin ``margin`` on every limit, or each limit's (None: the defaults for joint errors
    up to :data:`~pkmcal.planning.margins.ASSUMED_JOINT_ERROR_MM`)."""
    from pkmcal.io.lookup import load_machine, load_setup
    from pkmcal.planning.margins import has_margins, resolve_margin
    from pkmcal.study.printed import probes_the_bed

    mech = load_machine(machine)
    setup = load_setup(setup, mech)
    probe = probes_the_bed(setup.sensor)
    for given, name in ((probe_anywhere, "--probe-anywhere"), (target_accuracy is not None, "--target-accuracy"),
                        (fmt != "csv", f"--format {fmt}")):
        if given and not probe:
            raise PkmcalError(f"{name} is for a Z probe's plan; the setup's '{setup.sensor.kind}' sensor is not one")
    if fmt != "csv" and probe_anywhere:
        raise PkmcalError(f"--format {fmt} writes probes a printer runs on its bed; drop --probe-anywhere")
    if fmt != "csv" and units_comment:
        raise PkmcalError(f"--units-comment begins a CSV; --format {fmt} writes G-code")
    given = [n for n, v in (("--stroke-margin", stroke_margin), ("--tilt-margin", tilt_margin),
                            ("--clearance-margin", clearance_margin)) if v is not None]
    if margin is not None and given:
        raise PkmcalError(f"--margin sets every limit's margin; give it or {', '.join(given)}, not both")
    if (given or margin is not None) and not has_margins(mech):
        raise PkmcalError(f"machine '{mech.name}' has no stroke or joint-tilt limits to keep a margin from "
                          "(its limits: workspace box, reach, transmission angle); remove the margin options")
    safety = margin if margin is not None else resolve_margin(mech, stroke_mm=stroke_margin, tilt_deg=tilt_margin,
                                                                clearance_mm=clearance_margin)
    return mech, setup, safety


@dataclass(frozen=True)
class PosePlan(Plan):
    """A :class:`~pkmcal.planning.plan.Plan` (``poses``, ``commands``, ``selection``,
    ``candidates``, ``model``, ``notes``, ``on_bed``) with the nominal machine and the setup it
    was chosen for, which knows its files and its summary (what ``pkmcal plan`` writes and
    prints): :meth:`csv`, :meth:`printer_file`, :meth:`summary`, :meth:`probe_facts`."""

    nominal: Any = None
    setup: Any = None

    @classmethod
    def of(cls, plan, nominal, setup) -> "PosePlan":
        """``plan`` (a :class:`~pkmcal.planning.plan.Plan`) with its ``nominal`` machine and ``setup``."""
        return cls(**{f.name: getattr(plan, f.name) for f in dataclasses.fields(plan)}, nominal=nominal, setup=setup)

    def csv(self, command: str, units_comment: bool = False) -> str:
        """The plan's poses and nominal commands as a CSV (file units), its comments the
        ``command``, the safety margin, the notes and the indices."""
        from pkmcal.io.tables import format_table, to_file_units

        mech, plan = self.nominal, self
        poses = to_file_units(plan.poses, mech.pose_is_angle)
        commands = to_file_units(plan.commands, mech.actuator_is_angle)
        cols = {name: poses[:, i] for i, name in enumerate(mech.pose_names)}
        cols.update({name: commands[:, i] for i, name in enumerate(mech.actuator_names)})
        sel = plan.selection
        return format_table(cols, units_comment=units_comment, comments=[
            f"{command}; maximised {sel.criterion}",
            f"safety margin: {plan.describe_margin()}",
            *(f"note: {n}" for n in plan.notes),
            format_indices(sel.indices)])

    def printer_file(self, fmt: str, command: str, machine: str, setup_spec: str) -> str:
        """The Klipper macro (``fmt="klipper"``) or Marlin G-code (``"gcode"``) of an on-bed
        Z-probe plan (:mod:`pkmcal.io.probe_gcode`); ``machine`` and ``setup_spec`` as the
        import command that reads its output names them."""
        from pkmcal.io.probe_gcode import klipper_probe_macro, marlin_probe_gcode

        offset = np.asarray(self.setup.sensor.probe_offset, dtype=float)
        nozzle = self.poses[:, 0:2]
        if fmt == "klipper":
            return klipper_probe_macro(nozzle, offset, [
                f"{command} --format klipper", "Paste into printer.cfg (or [include] this file), RESTART, run "
                "PKMCAL_PROBE_PLAN, save the console (or klippy.log), then:",
                f"  pkmcal import klipper-probe console.log --machine {machine} --setup {setup_spec} -o probe.csv"])
        return marlin_probe_gcode(nozzle + offset[None, 0:2], offset, [
            f"{command} --format gcode", "Run on the printer (print it from SD or send it), save the terminal's "
            "output, then:",
            f"  pkmcal import marlin-probe terminal.log --machine {machine} --setup {setup_spec} -o probe.csv"])

    def summary(self, target: float | None = None) -> dict:
        """What ``pkmcal plan`` prints, as a JSON-ready dict: the candidates, the safety
        margin, the identifiable parameters, the selection and its indices; for a Z probe on
        the bed, ``probe`` (:meth:`probe_facts`, with the points for the first-layer
        ``target`` sigma in mm)."""
        plan = self
        cand, sel, model = plan.candidates, plan.selection, plan.model
        out = {"candidates": {"accepted": int(len(cand.poses)), "tested": int(cand.n_tested), "kind": cand.kind,
                              "rejected": {k: int(v) for k, v in sorted(cand.rejected.items())},
                              "text": cand.describe()},
               "safety_margin": plan.describe_margin(), "notes": list(plan.notes),
               "identifiable_parameters": int(model.n_params), "method": model.method,
               "gauge_fixed": list(model.report.fixed),
               "selection": {"algorithm": sel.algorithm, "n_poses": int(len(sel.chosen)), "criterion": sel.criterion,
                             "message": sel.message},
               "indices": {k: _number(v) for k, v in sel.indices.items()}}
        if plan.on_bed:
            out["probe"] = self.probe_facts(target)
        return out

    def probe_facts(self, target: float | None = None) -> dict:
        """An on-bed Z-probe plan's facts: the probe offset (mm) and repeatability (the setup's
        noise.reading, mm, or None), the predicted first-layer error for other numbers of
        points (:func:`pkmcal.planning.plan.height_sigma`: ``first_layer_sigma_mm``,
        ``[points, mm]``), the points for ``target`` (``target``: ``{"sigma_mm", "points"``
        (None when not reached), ``"reached_sigma_mm"}``), and what heights cannot see and
        what would see it (``undetermined``: the sentences of
        :func:`~pkmcal.identification.identifiability.undetermined_directions`, the named
        directions and the rail leans, as ``identify`` says them)."""
        from pkmcal.identification.identifiability import undetermined_directions
        from pkmcal.planning.plan import height_sigma, points_for_height_sigma

        plan, setup = self, self.setup
        noise = setup.noise.reading_std
        n = len(plan.poses)
        ladder = sorted({k for k in (n // 2, n, 2 * n, 4 * n)
                         if plan.model.n_params <= k <= len(plan.candidates.poses)} | {n})
        curve = [(k, s) for k, s in height_sigma(plan, ladder) if np.isfinite(s)]
        facts: dict = {"offset_mm": [float(v) for v in np.asarray(setup.sensor.probe_offset, dtype=float)],
                       "repeatability_mm": float(noise[0]) if noise is not None and np.size(noise) else None,
                       "points": n, "first_layer_sigma_mm": [[int(k), float(s)] for k, s in curve]}
        if target is not None:
            need, tried = points_for_height_sigma(plan, target)
            facts["target"] = {"sigma_mm": float(target), "points": None if need is None else int(need),
                               "reached_sigma_mm": _number(tried[-1][1] if need is None else dict(tried)[need])}
        facts["undetermined"] = [entry["text"] for entry in
                                 undetermined_directions(plan.model.mechanism, setup, plan.poses)] if curve else []
        return facts


def plan_of(nominal, setup, n_poses: int, *, algorithm: str = "default", index: str | None = None,
            candidates=None, mapping=None, n_candidates: int = 2000, grid: int | None = None, seed=0,
            margin=None, measurability=None, circle_plane: str = "xy", probe_anywhere: bool = False,
            workers: int | None = None, dask_address: str | None = None,
            progress: Callable[[], Any] | None = None) -> PosePlan:
    """``pkmcal plan``'s selection on the machine and setup of :func:`plan_inputs`:
    ``candidates`` a pose file (read with ``mapping``) or None (``n_candidates`` random ones,
    or a ``grid``); the candidates' checks and blocks on ``workers`` processes or a Dask
    cluster (:func:`pkmcal.planning.executors.chunk_map`); ``progress`` makes the progress
    bar (a context manager whose ``stage`` the planning reports to)."""
    from pkmcal.planning.candidates import Measurability, read_candidates_csv
    from pkmcal.planning.executors import chunk_map
    from pkmcal.planning.plan import plan_poses

    if candidates is not None and not isinstance(candidates, np.ndarray):
        candidates = read_candidates_csv(candidates, nominal, mapping)
    with chunk_map(workers, dask_address) as run_chunks, \
            (progress() if progress is not None else contextlib.nullcontext()) as bar:
        plan = plan_poses(nominal, setup, n_poses, algorithm=algorithm, index=index.upper() if index else None,
                          candidates=candidates, n_candidates=n_candidates, grid=grid, seed=seed, margin=margin,
                          measurability=Measurability() if measurability is None else measurability,
                          progress=None if bar is None else bar.stage, circle_plane=circle_plane,
                          chunk_map=run_chunks, on_bed=False if probe_anywhere else None)
    return PosePlan.of(plan, nominal, setup)


@dataclass
class PatternPlan:
    """What :func:`iso9283_plan` laid out: the nominal machine and the
    :class:`~pkmcal.identification.iso9283.Iso9283Pattern` (``center``, ``side``, ``cycles``,
    ``notes``)."""

    nominal: Any
    pattern: Any

    @property
    def centre_text(self) -> str:
        return ", ".join(f"{v:.6g}" for v in self.pattern.center)

    def csv(self, command: str, units_comment: bool = False) -> str:
        """The pattern as a CSV: poses, nominal commands, ``iso_pose`` 1..5, ``cycle``."""
        from pkmcal.io.tables import format_table, to_file_units

        mech, pat = self.nominal, self.pattern
        poses, label, cycle = pat.cycle_poses()
        cols = {name: to_file_units(poses, mech.pose_is_angle)[:, i] for i, name in enumerate(mech.pose_names)}
        commands = to_file_units(mech.ik(poses), mech.actuator_is_angle)
        cols.update({name: commands[:, i] for i, name in enumerate(mech.actuator_names)})
        cols.update({"iso_pose": label, "cycle": cycle})
        return format_table(cols, units_comment=units_comment, comments=[
            command, f"ISO 9283 cube: centre {self.centre_text} mm, side {pat.side:.6g} mm; P1..P5 on its diagonal "
            f"plane C1-C2-C7-C8, {pat.cycles} cycles", *(f"note: {n}" for n in pat.notes)])

    @property
    def n_poses(self) -> int:
        return 5 * int(self.pattern.cycles)

    def summary(self) -> dict:
        """``plan --pattern iso9283 --json``: ``pattern``, ``centre_mm``, ``side_mm``, ``cycles``,
        ``n_poses``, ``notes``."""
        pat = self.pattern
        return {"pattern": "iso9283", "centre_mm": [float(v) for v in pat.center], "side_mm": float(pat.side),
                "cycles": int(pat.cycles), "n_poses": self.n_poses, "notes": list(pat.notes)}


def iso9283_plan(nominal, setup, cycles: int | None = None, *, margin=None, measurability=None) -> PatternPlan:
    """``plan --pattern iso9283``: P1..P5 on the diagonal plane of the largest cube that passes
    the limits with the safety ``margin`` and the setup's ``measurability``, in ``cycles``
    cycles (None: ISO 9283 §7.2.1's 30)."""
    from pkmcal.identification.iso9283 import CYCLES, iso9283_pattern

    pat = iso9283_pattern(nominal, setup, cycles=CYCLES if cycles is None else cycles, margin=margin,
                          measurability=measurability)
    return PatternPlan(nominal, pat)


@dataclass
class Observability:
    """What :func:`observability_of` found: the machine, the poses (internal units), the
    indices O1..O5 and warnings (``notes``: rows the machine cannot reach)."""

    nominal: Any
    setup: Any
    poses: np.ndarray
    indices: dict
    notes: list[str] = field(default_factory=list)


def observability_of(machine, setup, poses, *, mapping=None) -> Observability:
    """``pkmcal observability MACHINE --setup SETUP --poses POSES.csv``: ``machine`` and
    ``setup`` files or built-in names, ``poses`` a pose file (read with ``mapping``); O1..O5 on
    the scaled, noise-weighted identification Jacobian restricted to the identifiable
    parameters (as :func:`plan_of`)."""
    from pkmcal.io.lookup import load_machine, load_setup
    from pkmcal.planning.candidates import read_candidates_csv
    from pkmcal.planning.plan import pose_set_indices
    from pkmcal.workflow.analysis import unreachable_notes

    mech = load_machine(machine)
    setup = load_setup(setup, mech)
    pose_arr = read_candidates_csv(poses, mech, mapping)
    ind = pose_set_indices(mech, setup, pose_arr)
    return Observability(mech, setup, pose_arr, ind, unreachable_notes(mech, pose_arr, poses))
