"""``pkmcal demo``: a complete calibration, planned, simulated, identified, verified, exported.

On the default machine (``stewart-prototype``, paper 2 §5, Table 3) with its built-in "real"
counterpart (``stewart-prototype-real``: Table 4's joint and offset errors of 1–3 mm):

1. **plan** (:func:`pkmcal.planning.plan.plan_poses`) — checked random candidate poses of
   the workspace box, their whitened, scaled identification-Jacobian blocks G_j
   (:mod:`pkmcal.planning.blocks`) and a D-optimal selection max log det Σ G_jᵀG_j
   (:mod:`pkmcal.planning.selection`, paper 2 §4). Candidates are
   checked against the nominal machine with the safety margins of ``pkmcal plan``
   (:mod:`pkmcal.planning.margins`: stroke, joint tilts, leg clearance), so that the real
   machine — whose joints differ by millimetres — still reaches them. With ``poses`` (a
   poses file) the plan is that file instead;
2. **simulate** the campaign on the real machine (:mod:`pkmcal.identification.simulation`,
   paper 1 §IV): q = IK(x_c, ρ_nom), x_r = FK(q, ρ_real), y = h(x_r) + noise;
3. **identify** the 42 parameters (:func:`pkmcal.workflow.calibrate`, as ``pkmcal identify``:
   :func:`pkmcal.identification.engine.identify` and the refusal of a bad fit; the
   method the setup calls for: ``ik-residual`` for full pose, paper 1 §V; ``fk-residual``
   for indicators, paper 2 §3);
4. **verify** on held-out poses, not used for identification
   (:mod:`pkmcal.identification.verification`): e_p = ‖p_r − p_c‖, e_R = ∠(R_r R_cᵀ), with
   the nominal model (before) and the identified one (after), and an error map;
5. **export** the calibrated machine (YAML), LinuxCNC genhexkins HAL settings, a JSON
   summary, the measurements and the poses (CSV);
6. **report**: ``report.html`` and its figures (:mod:`pkmcal.report`).

The default setup is paper 1's full-pose measurement (``full-pose-paper1``: uniform noise
±0.025 mm, ±0.001 rad, legs ±0.01 mm); ``indicators-prototype`` (paper 2's three dial
indicators) is the other built-in choice. Every random draw comes from one seed, so the
same seed writes the same bytes.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from pkmcal import __version__
from pkmcal.conventions import POSE_COLUMNS, angle_text, length_text, poses_to_file_units
from pkmcal.errors import PkmcalError

DEMO_MACHINE = "stewart-prototype"
DEMO_REAL = "stewart-prototype-real"
DEMO_SETUP = "full-pose-paper1"
DEMO_OUT = "pkmcal-demo"

#: Demo steps, in order, as reported to the progress callback.
STEPS = ("plan", "simulate", "identify", "verify", "export", "report")

#: progress(step_number (1-based), n_steps, step name, message): called as each step starts
#: (message "") and ends (message: what it did).
Progress = Callable[[int, int, str, str], None]


@dataclass(frozen=True)
class DemoConfig:
    """What the demo does. Lengths mm, angles degrees (as on the command line)."""

    machine: str = DEMO_MACHINE
    real: str = DEMO_REAL
    setup: str = DEMO_SETUP
    out: str = DEMO_OUT
    seed: int = 0
    n_poses: int = 40
    n_candidates: int = 1000
    n_held_out: int = 100
    stroke_margin: float | None = None        # None: the default of pkmcal.planning.margins
    tilt_margin_deg: float | None = None      # None: the default of pkmcal.planning.margins
    error_map_points: int = 31
    png: bool = True
    poses: str | None = None                  # a poses file measured instead of a planned set

    def __post_init__(self) -> None:
        for name in ("n_poses", "n_candidates", "n_held_out", "error_map_points"):
            if int(getattr(self, name)) < 1:
                raise PkmcalError(f"demo: {name.replace('_', ' ')} must be a positive integer; "
                                  f"got {getattr(self, name)}")
        if self.n_candidates < self.n_poses:
            raise PkmcalError(f"demo: {self.n_poses} poses cannot be chosen from {self.n_candidates} candidates; "
                              "ask for more candidates or fewer poses")
        for name in ("stroke_margin", "tilt_margin_deg"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise PkmcalError(f"demo: {name.replace('_', ' ')} must be a non-negative number; got {v}")


@dataclass(frozen=True)
class DemoResult:
    """What the demo produced: the output folder, the files written (label → path), the
    planned and held-out poses, the engine's and verifier's results, and headline numbers
    (``headline``: held-out position/orientation rms and max before/after, mm and rad)."""

    out: Path
    files: dict[str, Path]
    planned: np.ndarray
    held_out: np.ndarray
    simulation: object
    identification: object
    verification: object
    headline: dict[str, float]
    notes: tuple[str, ...] = field(default_factory=tuple)

    def summary(self) -> str:
        """Closing summary for the terminal."""
        h = self.headline
        v = self.verification.to_dict()
        lines = [
            f"Held-out verification on {v['used']} poses not used for identification:",
            f"  position error    rms {length_text(h['position_rms_before']):>10} -> "
            f"{length_text(h['position_rms_after']):>10}   (max {length_text(h['position_max_before'])} -> "
            f"{length_text(h['position_max_after'])})",
            f"  orientation error rms {angle_text(h['orientation_rms_before']):>10} -> "
            f"{angle_text(h['orientation_rms_after']):>10}   (max {angle_text(h['orientation_max_before'])} -> "
            f"{angle_text(h['orientation_max_after'])})",
            f"Report:  {self.files['report']}",
            "Files:   " + ", ".join(p.name for k, p in self.files.items() if k != "report"),
        ]
        lines += [f"Note:    {n}" for n in self.notes]
        return "\n".join(lines)


def _safe_planning_machine(machine, config: DemoConfig):
    """The nominal hexapod with its limits shrunk by the plan's safety margins
    (:mod:`pkmcal.planning.margins`; the config's stroke and tilt margins where given), and
    those margins."""
    from pkmcal.mechanisms.hexapod import Hexapod
    from pkmcal.planning.margins import planning_machine, resolve_margin

    if machine.kind != Hexapod.kind:   # the margins of planning_machine are the 6-UPS hexapod's
        raise PkmcalError(f"pkmcal demo runs on {Hexapod.kind} hexapods; machine '{machine.name}' is a "
                          f"{machine.kind} machine")
    margin = resolve_margin(machine, stroke_mm=config.stroke_margin, tilt_deg=config.tilt_margin_deg)
    return planning_machine(machine, margin), margin


def _finite(obj):
    """JSON-safe copy: non-finite floats → None, numpy scalars/arrays → Python."""
    if isinstance(obj, dict):
        return {str(k): _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _finite(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    return obj


def _pose_columns(poses: np.ndarray) -> dict[str, np.ndarray]:
    f = poses_to_file_units(poses)
    return {c: f[:, k] for k, c in enumerate(POSE_COLUMNS)}


def run_demo(config: DemoConfig = DemoConfig(), progress: Progress | None = None) -> DemoResult:
    """Run the demo pipeline (module docstring) and write its files into ``config.out``.

    ``progress(k, n, step, message)`` is called when each of the :data:`STEPS` starts
    (message "") and ends (message: what it did).
    """
    from pkmcal.identification.simulation import simulate_campaign
    from pkmcal.identification.verification import verify
    from pkmcal.io.atomic import atomic_write_text, make_folder
    from pkmcal.io.export_linuxcnc import linuxcnc_hal
    from pkmcal.io.machine_file import load_machine, save_machine
    from pkmcal.io.measurements import save_measurements
    from pkmcal.io.setup_file import load_setup, setup_to_yaml
    from pkmcal.io.tables import write_table
    from pkmcal.planning.blocks import default_method, planning_model
    from pkmcal.planning.candidates import generate_candidates
    from pkmcal.planning.plan import plan_poses
    from pkmcal.report import write_report
    from pkmcal.report.from_results import error_map, report_data_from_results
    from pkmcal.workflow.calibration import calibrate

    report = progress or (lambda k, n, step, msg: None)
    n_steps = len(STEPS)

    def step(name: str, message: str = "") -> None:
        report(STEPS.index(name) + 1, n_steps, name, message)

    out = Path(config.out)
    if out.exists() and not out.is_dir():
        raise PkmcalError(f"demo output '{out}' exists and is not a folder; choose another with -o")
    nominal = load_machine(config.machine)
    real = load_machine(config.real)
    setup = load_setup(config.setup)
    method = default_method(setup, nominal)
    seed_plan, seed_sim, seed_held = np.random.SeedSequence(config.seed).generate_state(3)
    rng_sim, rng_held = np.random.default_rng(int(seed_sim)), np.random.default_rng(int(seed_held))
    notes: list[str] = []

    # 1. plan ---------------------------------------------------------------------------
    step("plan")
    safe, margin = _safe_planning_machine(nominal, config)
    pm = planning_model(nominal, setup, method=method)
    if config.poses is None:
        plan = plan_poses(nominal, setup, config.n_poses, algorithm="default", n_candidates=config.n_candidates,
                          seed=int(seed_plan), method=method, model=pm, margin=margin)
        selection, pool = plan.selection, plan.candidates.poses
        planned = pool[np.sort(selection.chosen)]
        planning = {"candidates": int(len(pool)), "chosen": int(len(planned)), "algorithm": selection.algorithm,
                    "criterion": selection.criterion, "indices": selection.indices, "parameters": list(pm.names),
                    "safety_margin": {"stroke_mm": margin.stroke_mm, "tilt_deg": margin.tilt_deg,
                                      "clearance_mm": margin.clearance_mm, "source": margin.source}}
        plan_text = (f"{len(planned)} D-optimal poses of {len(pool)} random candidates; safety margin "
                     f"{margin.describe()}")
        step("plan", f"{len(planned)} poses chosen from {len(pool)} candidates (D-optimal, {pm.n_params} parameters; "
                     f"O1 = {selection.indices['O1']:.3g}); safety margin {margin.describe()}")
    else:
        from pkmcal.io.tables import read_poses
        from pkmcal.planning.plan import pose_set_indices

        planned = pool = read_poses(config.poses, nominal)
        indices = pose_set_indices(nominal, setup, planned, model=pm)
        planning = {"file": str(config.poses), "chosen": int(len(planned)), "indices": indices,
                    "parameters": list(pm.names)}
        plan_text = f"{len(planned)} poses of the file {config.poses}"
        step("plan", f"{len(planned)} poses read from {config.poses} (O1 = {indices['O1']:.3g})")

    # 2. simulate -----------------------------------------------------------------------
    step("simulate")
    sim = simulate_campaign(nominal, real, setup, planned, rng=rng_sim)
    if sim.dropped:
        notes.append(sim.summary().replace("\n", ";"))
    step("simulate", f"{len(sim.kept)} of {len(planned)} poses measured on '{real.name}' ({setup.sensor.kind} sensor)")

    # 3. identify -----------------------------------------------------------------------
    step("identify")
    # the fit and its verdict as 'pkmcal identify' makes them (a refused fit is an error); every
    # simulated pose is used (a reading at a stroke's end is the simulation's, not a clipped one)
    result = calibrate(nominal, setup, sim.measurements, method=method, clipped="keep", where=str(out)).result
    calibrated = result.mechanism.with_params(result.mechanism.params, name=f"{nominal.name}-calibrated",
                                              covariance=result.mechanism.covariance)
    calibrated = replace(calibrated, description=f"{nominal.name} calibrated by pkmcal demo (seed {config.seed}, "
                                                 f"{len(result.used_poses)} poses, {method})")
    step("identify", f"{len(result.free)} parameters, {result.method}, rms residual "
                     f"{length_text(result.rms_residual)}, {result.nfev} evaluations")

    # 4. verify -------------------------------------------------------------------------
    step("verify")
    held = generate_candidates(safe, setup, kind="random", n=config.n_held_out, rng=rng_held, margin=0.0).poses
    verification = verify(calibrated, real, held, nominal)
    m = verification.common
    summaries = verification.to_dict()  # over the poses both models reach (m)
    headline = {f"{q}_{stat}_{when}": summaries[when][f"{q}_{stat}_{unit}"]
                for q, unit in (("position", "mm"), ("orientation", "rad"))
                for stat in ("rms", "max") for when in ("before", "after")}
    k = config.error_map_points
    lo, hi = pool[:, :2].min(axis=0), pool[:, :2].max(axis=0)
    emap = error_map(nominal, calibrated, real, np.linspace(lo[0], hi[0], k), np.linspace(lo[1], hi[1], k),
                     float(nominal.home_pose[2]))
    step("verify", f"{int(m.sum())} held-out poses: position rms {length_text(headline['position_rms_before'])} "
                   f"-> {length_text(headline['position_rms_after'])}")

    # 5. export -------------------------------------------------------------------------
    step("export")
    make_folder(out, "-o")
    files: dict[str, Path] = {}
    files["calibrated"] = out / f"{calibrated.name}.yaml"
    save_machine(calibrated, files["calibrated"])
    files["linuxcnc"] = out / f"{calibrated.name}.hal"
    atomic_write_text(files["linuxcnc"], linuxcnc_hal(calibrated))
    files["setup"] = out / "setup.yaml"
    atomic_write_text(files["setup"], setup_to_yaml(setup))
    files["poses"] = out / "planned-poses.csv"
    write_table(files["poses"], _pose_columns(planned), comments=(f"pkmcal demo: {len(planned)} planned poses, "
                                                                  f"seed {config.seed}",))
    files["measurements"] = out / "measurements.csv"
    save_measurements(files["measurements"], sim.measurements, nominal, setup,
                      comments=(f"simulated on {real.name}, seed {config.seed}",))
    files["held_out"] = out / "held-out-poses.csv"
    write_table(files["held_out"], _pose_columns(held), comments=(f"pkmcal demo: held-out poses, seed {config.seed}",))
    summary = {
        "pkmcal": __version__,
        "demo": _finite({k: v for k, v in asdict(config).items() if k != "out"}),
        "machine": nominal.name,
        "real_machine": real.name,
        "setup": setup.sensor.kind,
        "planning": planning,
        "simulation": {"measured": int(len(sim.kept)),
                       "dropped": [{"pose": int(i) + 1, "reason": r} for i, r in sim.dropped.items()]},
        "identification": result.to_dict(),
        "verification": verification.to_dict(),
        "headline_mm_deg": {k: math.degrees(v) if k.startswith("orientation") else v for k, v in headline.items()},
        "headline_mm_rad": headline,
        "units": {"seed": "1", "n_poses": "1", "n_candidates": "1", "n_held_out": "1", "error_map_points": "1",
                  "stroke_margin": "mm", "candidates": "1", "chosen": "1", "indices": "1", "measured": "1",
                  "headline_mm_deg": "mm for position_*, deg for orientation_*",
                  "headline_mm_rad": "deprecated: headline_mm_deg with the orientation in radians"},
    }
    files["json"] = out / "calibration.json"
    atomic_write_text(files["json"], json.dumps(_finite(summary), indent=2, ensure_ascii=False) + "\n")
    step("export", ", ".join(p.name for p in files.values()))

    # 6. report -------------------------------------------------------------------------
    step("report")
    data = report_data_from_results(
        nominal, result, setup, sim.commanded[sim.kept],
        verification=verification, identified=calibrated, true_machine=real, true_sensor=setup.sensor,
        error_map=emap,
        held_out_poses=held[m],
        title=f"pkmcal demo: calibration of {nominal.name}",
        setup_summary=setup_to_yaml(setup),
        facts=(("real machine (simulated)", real.name), ("seed", str(config.seed)),
               ("pose plan", plan_text),
               ("held-out poses", f"{int(m.sum())} of {len(held)} (random, other seed)"),
               ("calibrated machine file", files["calibrated"].name),
               ("LinuxCNC settings", files["linuxcnc"].name)),
        calibrated_file=files["calibrated"].name, setup_name=files["setup"].name,
    )
    written = write_report(data, out, png=config.png)
    files["report"] = written.html
    step("report", f"{written.html} and {len(written.figures)} figure files")
    return DemoResult(out=out, files=files, planned=planned, held_out=held, simulation=sim,
                      identification=result, verification=verification, headline=headline, notes=tuple(notes))
