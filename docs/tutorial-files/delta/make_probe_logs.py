"""Make the probe logs of docs/tutorial-delta-printer.md: a simulated real printer probed as
Klipper probes it, written as Klipper prints it.

There is no real printer attached to the tutorial, so this script stands in for one: a
delta whose geometry differs from its printer.cfg as a kit-built Kossel's does. Run from
the repository root (it rewrites the two logs byte for byte; fixed seed)::

    PYTHONPATH=src python3 docs/tutorial-files/delta/make_probe_logs.py

and, since the truth is known here, it says how the real printer prints with a config
(``--check printer.cfg saved.cfg``: the files Klipper would read, later sections winning,
as when saved.cfg's sections replace printer.cfg's): the nozzle heights over the bed where
the firmware puts z = 0 (the first layer) and the errors of 100 mm distances printed at the
centre (dimensional accuracy)::

    PYTHONPATH=src python3 docs/tutorial-files/delta/make_probe_logs.py --check printer.cfg saved.cfg

The real printer (``REAL`` below): the config's nominal Kossel (rods 215 mm, radius
105.2 mm, endstops 250 mm, towers at 210/330/90°), but its rods are 215.12, 214.93 and
215.06 mm (a set measured 215 ± 0.1 mm), the carriage-to-effector radius is 104.6 mm and
not the same on each tower (tower b 0.25 mm further out), the endstop switches sit at
250.62, 249.71 and 250.38 mm, towers a and b stand 0.35° and −0.25° off their angles, and
rail b leans 0.15° towards the centre (a frame a little out of square). The bed is flat
and level at z = 0; the probe is the nozzle (Klipper's ``[probe] z_offset: 0``).

How Klipper probes (klippy/extras/probe.py, simulated): at each (x, y) the firmware lowers
the nozzle down *its own* vertical line (its kinematics: the config's numbers) until the
real nozzle touches the real bed (a trigger scatter of 0.005 mm std, a typical probe's
repeatability, which the built-in setup ``z-probe-klipper`` assumes). The steppers stop on
a whole step (rotation_distance 40 / (200 · 16) = 0.0125 mm); the firmware reports the
position its kinematics compute from those step counts: ``probe: at X,Y bed will contact
at z=Z`` (3 decimals for X, Y; 6 for Z). A real nozzle touching a real bed at z = 0 is
reported at a z that is not 0 where the config is wrong: that spread is the first-layer
flatness error.

* ``probe.log``: the ``PROBE_RINGS`` macro of printer.cfg (37 points: the centre and rings
  of 25, 50 and 75 mm), the calibration data.
* ``check.log``: 20 points drawn uniformly in the 80 mm disc (``BED_MESH``-like, not on the
  rings), kept out of the fit to check it.
"""

from __future__ import annotations

import os
import sys
import tempfile

import numpy as np

from pkmcal.io.delta_firmware import read_klipper
from pkmcal.io.setup_file import load_setup
from pkmcal.mechanisms.linear_delta import PARAM_NAMES

HERE = os.path.dirname(os.path.abspath(__file__))
SEED = 2027
#: The real printer's parameters that differ from printer.cfg (mm, degrees).
REAL = {"arm_a": 215.12, "arm_b": 214.93, "arm_c": 215.06,
        "radius_a": 104.6, "radius_b": 104.85, "radius_c": 104.6,
        "endstop_a": 250.62, "endstop_b": 249.71, "endstop_c": 250.38,
        "angle_a": 210.35, "angle_b": 329.75, "lean_radial_b": 0.15}
TRIGGER_STD = 0.005                 # mm
STEP = 40.0 / (200 * 16)            # mm per step


def real_printer(firmware):
    """The real machine: the config's machine with :data:`REAL`; readings are the firmware's
    stepper positions (its reading reference), as on the printer."""
    rho = firmware.params.copy()
    for name, value in REAL.items():
        k = PARAM_NAMES.index(name)
        rho[k] = np.deg2rad(value) if firmware.param_is_angle[k] else value
    return firmware.with_params(rho, name="real-printer")


def probe(firmware, real, sensor, xy, rng):
    """Klipper's PROBE at each (x, y): carriage positions at the trigger on the step grid,
    and the nozzle positions the firmware reports from them."""
    target = rng.standard_normal(len(xy)) * TRIGGER_STD  # the probe triggers this far from the bed

    def height(z):
        lam = firmware.ik(np.c_[xy, z])
        return sensor.predict(real.frame(real.fk(lam).poses))[:, 0] - target, lam

    z, dz = np.zeros(len(xy)), 1e-3
    for _ in range(30):           # secant steps down the firmware's vertical line
        h0, _ = height(z)
        h1, _ = height(z + dz)
        z = z - h0 * dz / (h1 - h0)
    h, lam = height(z)
    assert np.max(np.abs(h)) < 1e-10
    ref = firmware.reading_reference
    steps = np.round((ref[None, :] - lam) / STEP)          # whole steps below the endstop
    fk = firmware.fk(ref[None, :] - steps * STEP)
    assert fk.ok.all()
    return fk.poses


def log_lines(title: str, poses) -> str:
    lines = [f"// {title}"]
    for x, y, z in poses:
        lines += ["PROBE", f"// probe: at {x:.3f},{y:.3f} bed will contact at z={z:.6f}", f"// Result is z={z:.6f}"]
    return "\n".join(lines) + "\n"


def check(*configs: str) -> list[str]:
    """How the real printer prints under the Klipper config made of ``configs`` (later
    sections win): the real nozzle's height over the bed where the firmware puts z = 0 on a
    grid of the 75 mm disc (the first layer), and the error of three 100 mm distances
    (along x, y and the diagonal, at the centre, z = 0.2 mm) as the real printer makes them.
    Readings convert through the switches, which do not move: travel below each switch is
    the same on both configs, λ_cfg − H_cfg = λ − H (H the switch readings)."""
    text = ""
    for c in configs:
        with open(c, encoding="utf-8") as fh:
            text += fh.read() + "\n"
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "printer.cfg")
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(text)
        cfg = read_klipper(path).machine("config")
    built = read_klipper(os.path.join(HERE, "printer.cfg")).machine("printer")
    real = real_printer(built)

    def real_nozzle(p):
        lam = cfg.ik(p) - cfg.reading_reference + built.reading_reference
        return real.fk(lam).poses

    g = np.linspace(-75.0, 75.0, 31)
    X, Y = np.meshgrid(g, g)
    inside = X**2 + Y**2 <= 75.0**2
    z = real_nozzle(np.c_[X[inside], Y[inside], np.zeros(inside.sum())])[:, 2]
    ends = np.array([[-50, 0], [50, 0], [0, -50], [0, 50], [-35.355339, -35.355339], [35.355339, 35.355339]])
    p = np.c_[ends, np.full(6, 0.2)]
    q = real_nozzle(p)
    errs = [np.linalg.norm(q[2 * k + 1] - q[2 * k]) - np.linalg.norm(p[2 * k + 1] - p[2 * k]) for k in range(3)]
    return [(f"first layer (z = 0, {int(inside.sum())} points of the 75 mm disc): the real nozzle {z.mean():+.3f} mm "
             f"above the bed on average, spread {z.max() - z.min():.3f} mm (max - min), std {np.std(z):.4f} mm"),
            "100 mm printed as: " + ", ".join(f"{100 + e:.3f} mm along {d}" for e, d in
                                                zip(errs, ("x", "y", "the diagonal")))]


def main(argv: list[str]) -> None:
    if argv[:1] == ["--check"]:
        print("\n".join(check(*argv[1:])))
        return
    firmware = read_klipper(os.path.join(HERE, "printer.cfg")).machine("printer")
    real = real_printer(firmware)
    sensor = load_setup("z-probe-klipper", firmware).sensor
    rng = np.random.default_rng(SEED)
    rings = [(0.0, 1), (25.0, 6), (50.0, 12), (75.0, 18)]
    xy = np.array([(r * np.cos(a), r * np.sin(a)) for r, n in rings for a in 2 * np.pi * np.arange(n) / n])
    fit = probe(firmware, real, sensor, xy, rng)
    r = 80.0 * np.sqrt(rng.uniform(size=20))
    t = rng.uniform(0, 2 * np.pi, 20)
    held = probe(firmware, real, sensor, np.c_[r * np.cos(t), r * np.sin(t)], rng)
    for name, poses, title in (("probe.log", fit, "Mainsail console: PROBE_RINGS (printer.cfg's macro)"),
                               ("check.log", held, "Mainsail console: PROBE at 20 points off the rings")):
        with open(os.path.join(HERE, name), "w", encoding="utf-8", newline="\n") as fh:
            fh.write(log_lines(title, poses))
        z = poses[:, 2]
        print(f"{name}: {len(z)} points; reported z from {z.min():.3f} to {z.max():.3f} mm: a spread of "
              f"{z.max() - z.min():.3f} mm, std {np.std(z):.3f} mm about the mean (printer.cfg's flatness error)")


if __name__ == "__main__":
    main(sys.argv[1:])
