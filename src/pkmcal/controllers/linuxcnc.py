"""Run pkmcal's LinuxCNC export through the real LinuxCNC and compare it with pkmcal's model.

The controller is Debian's ``linuxcnc-uspace`` (LinuxCNC 2.9), started headless on a small
machine configuration made around the exported files (:func:`headless_config`):

* the HAL file is the export (``setp genhexkins.*``; a user's HAL file that does more, such as
  loading hardware drivers, is reduced to its genhexkins values,
  :func:`pkmcal.io.import_linuxcnc.read_hal_genhexkins`), run after LinuxCNC's simulated
  machine ``LIB:basic_sim.tcl`` (which loads ``[KINS] KINEMATICS`` and ``motmod`` and feeds each
  joint's command back as its position);
* the INI keys pkmcal owns (:data:`pkmcal.io.export_linuxcnc.OWNED_KEYS`: units, ``[TRAJ]
  HOME``, ``[KINS]``, the ``[JOINT_N]`` limits and home values) come from the exported INI;
  the rest (task, motion, velocities, axis limits, immediate homing) is generated here, with
  velocities high enough that a pose takes a fraction of a second;
* ``[DISPLAY] DISPLAY`` is :mod:`pkmcal.controllers._linuxcnc_display`, a program run by
  Debian's ``/usr/bin/python3`` (the one with LinuxCNC's ``linuxcnc`` module) that homes,
  moves by MDI ``G53 G0 X Y Z A B C`` (world mode: genhexkins' inverse kinematics gives the
  joints) and by joint jogs (joint mode: its forward kinematics gives the pose), and writes
  what LinuxCNC reports.

What a run needs and why (found running it in a container as root, no real-time kernel, no
display): ``rtapi_app`` refuses to run as root unless ``RTAPI_UID`` names an unprivileged uid
and ``RTAPI_FIFO_PATH`` names its socket in a directory that uid can write (here ``nobody`` and
a socket in a fresh directory; rtapi_app binds that path, so a directory there makes every
module load wait for a master that never starts); ``linuxcnc -r`` keeps the output on our
pipe instead of files in ``$HOME``;
``-no_use_hal_manualtoolchange`` keeps basic_sim from opening a Tk window; ``DISPLAY`` is
removed from the environment. LinuxCNC is one instance per host (its lock file
``/tmp/linuxcnc.lock``, fixed shared-memory keys, and a clean-up that finds its processes by
name, ``scripts/linuxcnc.in`` ``Cleanup``), so runs take a host-wide lock
(:data:`LOCK_FILE`) and refuse to start while another LinuxCNC holds its own. A run is never
killed from outside (rtapi_app leaves the process group, and the clean-up must run): on a time
out the DISPLAY program is stopped, which makes LinuxCNC shut itself down.

What is compared (:func:`check_machine`), in mm of the machine (the controller's units
converted once, ``[TRAJ] LINEAR_UNITS``):

* world mode: LinuxCNC's joints at a commanded pose against pkmcal's strut lengths
  L_i = ‖p + R a_i − b_i‖ of the same pose (``pkmcal ik``'s l1..l6); both are the same closed
  form (genhexkins.c ``genhexKinematicsInverse``), so they agree to rounding;
* joint mode: LinuxCNC's pose at the joints it holds after a jog against pkmcal's forward
  kinematics of those joints (``pkmcal fk``). genhexkins.c ``genhexKinematicsForward`` stops
  its Newton iteration once every strut's error is below ``convergence-criterion`` (1e-9 of
  the controller's unit by default) and takes one more step, so its pose leaves strut residuals
  r ≤ 1e-9 unit; pkmcal's FK is exact to rounding (one polishing step), so the two poses
  differ by J⁻¹ r to first order, at most ‖J⁻¹‖₂ ‖r‖₂ with J = ∂L/∂(x, y, z, a, b, c)
  (:attr:`LinuxcncCheck.fk_bound`, twice that plus rounding).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import pwd
import shutil
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pkmcal.errors import PkmcalError, one_line

#: Debian's Python, the one LinuxCNC's ``linuxcnc`` module is installed for.
SYSTEM_PYTHON = "/usr/bin/python3"
#: pkmcal's host-wide lock: one LinuxCNC run at a time on this host.
LOCK_FILE = "/tmp/pkmcal-linuxcnc.lock"
#: LinuxCNC's own lock file (``scripts/linuxcnc.in``): present while any LinuxCNC runs.
LINUXCNC_LOCK = "/tmp/linuxcnc.lock"
#: The DISPLAY program (run by :data:`SYSTEM_PYTHON`) and the files it shares with us.
DISPLAY_PROGRAM = Path(__file__).with_name("_linuxcnc_display.py")
JOB_FILE, RESULT_FILE, PID_FILE = "pkmcal-job.json", "pkmcal-result.json", "pkmcal-display.pid"
#: genhexkins' default ``convergence-criterion`` (genhexkins.c ``genhexKinematicsSetup``):
#: the forward kinematics stops when every strut error is below it (controller units).
GENHEXKINS_CONVERGENCE = 1e-9
#: Speeds of the generated configuration, per second, in mm (and degrees): a pose in a
#: fraction of a second; the simulated joints follow their command exactly, so no following
#: error limits them.
_SPEED_MM, _ACCEL_MM, _SPEED_DEG, _ACCEL_DEG = 2000.0, 20000.0, 720.0, 7200.0
#: LinuxCNC's joints at a commanded pose must equal pkmcal's strut lengths to this (mm): both
#: evaluate the same closed form, so what is left is rounding (about 1e-13 mm seen). The
#: export's rounding of the numbers to 1 nm (:data:`pkmcal.io.export_linuxcnc.LINUXCNC_ROUNDING`)
#: is allowed besides (:attr:`LinuxcncCheck.rounding`).
IK_TOLERANCE_MM = 1e-9
#: Servo period of the generated configuration (s).
_SERVO_PERIOD = 1e-3
#: Axis limits of the generated configuration (mm, degrees): wide open, so that only the
#: exported joint limits bound the motion.
_AXIS_RANGE_MM, _AXIS_RANGE_DEG = 1e5, 1e3


class LinuxcncMissing(PkmcalError):
    """LinuxCNC (or its Python module for :data:`SYSTEM_PYTHON`) is not installed here."""


def missing_reason() -> str | None:
    """Why LinuxCNC cannot run here (one line), or None when it can."""
    if shutil.which("linuxcnc") is None:
        return "LinuxCNC is not installed (no 'linuxcnc' command; Debian: apt-get install linuxcnc-uspace)"
    if not os.access(SYSTEM_PYTHON, os.X_OK):
        return f"{SYSTEM_PYTHON} is missing: LinuxCNC's Python module is installed for Debian's python3"
    probe = subprocess.run([SYSTEM_PYTHON, "-c", "import linuxcnc"], capture_output=True, text=True)
    if probe.returncode != 0:
        why = one_line(probe.stderr.strip())[-160:]
        return f"{SYSTEM_PYTHON} cannot import LinuxCNC's 'linuxcnc' module ({why}); install linuxcnc-uspace"
    return None


def require_linuxcnc() -> None:
    """Raise :class:`LinuxcncMissing` (exit code 2 from the CLI) when LinuxCNC cannot run."""
    reason = missing_reason()
    if reason is not None:
        raise LinuxcncMissing(reason)


# -- the configuration ---------------------------------------------------------------------

@dataclass(frozen=True)
class ControllerFiles:
    """The genhexkins HAL text and the INI keys pkmcal owns (``{(SECTION, KEY): value}``,
    sections and keys upper case), with the controller's units."""

    hal: str
    owned: dict[tuple[str, str], str]
    linear_unit: str
    mm_per_unit: float
    deg_per_unit: float
    source: str = "pkmcal export"

    def joint_limits_mm(self) -> np.ndarray | None:
        """The ``[JOINT_N] MIN_LIMIT, MAX_LIMIT`` (6, 2) in mm, or None when not all are given."""
        try:
            return np.array([[float(self.owned[(f"JOINT_{n}", key)]) * self.mm_per_unit
                              for key in ("MIN_LIMIT", "MAX_LIMIT")] for n in range(6)])
        except (KeyError, ValueError):
            return None


def controller_files(hal_text: str, ini_text: str, source: str = "pkmcal export") -> ControllerFiles:
    """:class:`ControllerFiles` of a HAL and an INI text (an export, or a user's files)."""
    from pkmcal.io.export_linuxcnc import HAL_PREFIX, OWNED_KEYS
    from pkmcal.io.import_linuxcnc import ANGULAR_UNITS, LINEAR_UNITS, read_hal_genhexkins, read_ini

    with tempfile.TemporaryDirectory(prefix="pkmcal-lcnc-read-") as tmp:
        ini_path, hal_path = os.path.join(tmp, "machine.ini"), os.path.join(tmp, "machine.hal")
        Path(ini_path).write_text(ini_text)
        Path(hal_path).write_text(hal_text)
        ini = read_ini(ini_path)
        values = read_hal_genhexkins(hal_path, ini)
    owned = {}
    for section, key in OWNED_KEYS:
        got = ini.get(section, key)
        if got is not None:
            owned[(section, key)] = got[0]
    live = [ln.strip() for ln in hal_text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not all(ln.startswith(f"setp {HAL_PREFIX}.") for ln in live):
        # a whole machine's HAL file (drivers, nets): keep only what it sets in genhexkins
        hal_text = "".join(f"setp {HAL_PREFIX}.{name} {value!r}\n" for name, (value, _) in values.items())
    unit = owned.get(("TRAJ", "LINEAR_UNITS"), "mm").strip().lower()
    angular = owned.get(("TRAJ", "ANGULAR_UNITS"), "degree").strip().lower()
    if unit not in LINEAR_UNITS or angular not in ANGULAR_UNITS:
        raise PkmcalError(f"{source}: [TRAJ] LINEAR_UNITS = {unit}, ANGULAR_UNITS = {angular}: not LinuxCNC units")
    return ControllerFiles(hal=hal_text, owned=owned, linear_unit=unit, mm_per_unit=LINEAR_UNITS[unit],
                           deg_per_unit=ANGULAR_UNITS[angular], source=source)


def headless_config(files: ControllerFiles, display: str, name: str = "pkmcal-check") -> str:
    """The INI text of a headless simulated machine around ``files`` (module docstring), its
    DISPLAY program ``display`` (an executable path without blanks)."""
    if any(ch.isspace() for ch in display):
        raise PkmcalError(f"the DISPLAY program path '{display}' contains blanks (LinuxCNC splits it into words)")
    u, d = files.mm_per_unit, files.deg_per_unit
    speed, accel = _SPEED_MM / u, _ACCEL_MM / u
    owned: dict[str, list[tuple[str, str]]] = {}
    for (section, key), value in files.owned.items():
        owned.setdefault(section, []).append((key, value))
    unit_code, _ = _program_units(u)

    def section(name: str, *keys: tuple[str, object]) -> list[str]:
        own = owned.get(name, [])
        mine = {k for k, _ in own}
        return ([f"[{name}]"] + [f"{k} = {v}" for k, v in own]
                + [f"{k} = {v}" for k, v in keys if k not in mine] + [""])

    lines = [f"# headless LinuxCNC machine written by pkmcal around {one_line(files.source)}", ""]
    lines += section("EMC", ("VERSION", "1.1"), ("MACHINE", one_line(name)), ("DEBUG", 0))
    lines += section("DISPLAY", ("DISPLAY", display), ("CYCLE_TIME", 0.05))
    lines += section("TASK", ("TASK", "milltask"), ("CYCLE_TIME", 0.001))
    lines += section("RS274NGC", ("PARAMETER_FILE", "pkmcal.var"),
                     ("RS274NGC_STARTUP_CODE", f"{unit_code} G90 G49 G92.1"))
    lines += section("EMCMOT", ("EMCMOT", "motmod"), ("COMM_TIMEOUT", 1.0),
                     ("SERVO_PERIOD", round(_SERVO_PERIOD * 1e9)))
    lines += section("HAL", ("HALFILE", "LIB:basic_sim.tcl -no_use_hal_manualtoolchange"),
                     ("HALFILE", "kinematics.hal"))
    lines += section("EMCIO", ("EMCIO", "io"), ("CYCLE_TIME", 0.1), ("TOOL_TABLE", "pkmcal.tbl"))
    lines += section("TRAJ", ("COORDINATES", "X Y Z A B C"), ("LINEAR_UNITS", "mm"), ("ANGULAR_UNITS", "degree"),
                     ("DEFAULT_LINEAR_VELOCITY", speed), ("MAX_LINEAR_VELOCITY", speed),
                     ("DEFAULT_LINEAR_ACCELERATION", accel), ("MAX_LINEAR_ACCELERATION", accel),
                     ("DEFAULT_ANGULAR_VELOCITY", _SPEED_DEG / d), ("MAX_ANGULAR_VELOCITY", _SPEED_DEG / d),
                     ("DEFAULT_ANGULAR_ACCELERATION", _ACCEL_DEG / d), ("MAX_ANGULAR_ACCELERATION", _ACCEL_DEG / d))
    lines += section("KINS", ("KINEMATICS", "genhexkins"), ("JOINTS", 6))
    for n in range(6):
        lines += section(f"JOINT_{n}", ("TYPE", "LINEAR"), ("MAX_VELOCITY", speed),
                         ("MAX_ACCELERATION", accel), ("HOME_SEQUENCE", 0))
    for axis in "XYZABC":
        lin = axis in "XYZ"
        rng = _AXIS_RANGE_MM / u if lin else _AXIS_RANGE_DEG / d
        lines += section(f"AXIS_{axis}", ("MIN_LIMIT", -rng), ("MAX_LIMIT", rng),
                         ("MAX_VELOCITY", speed if lin else _SPEED_DEG / d),
                         ("MAX_ACCELERATION", accel if lin else _ACCEL_DEG / d))
    return "\n".join(lines)


# -- a run ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class LinuxcncRun:
    """What LinuxCNC reported, in its own units (lengths in ``linear_unit``, angles in
    degrees): after homing, per commanded pose (world mode), per jog target (joint mode)."""

    linear_unit: str
    mm_per_unit: float
    home_joints: np.ndarray          # (6,)
    home_world: np.ndarray           # (6,)
    commanded: np.ndarray            # (N, 6) the poses sent by MDI G53 G0
    joints: np.ndarray               # (N, 6) joint_actual_position at them
    world: np.ndarray                # (N, 6) actual_position at them
    jog_targets: np.ndarray          # (M, 6) joint targets
    joints_held: np.ndarray          # (M, 6) the joints after the jogs
    jog_world: np.ndarray            # (M, 6) actual_position there (genhexkins' forward kinematics)
    stop_tolerance: float            # TINY_DP of the joints' planner (controller units): see stop_tolerance()
    seconds: float
    log: str = field(repr=False, default="")


@contextlib.contextmanager
def host_lock(wait: float = 600.0):
    """Hold :data:`LOCK_FILE` (waiting up to ``wait`` s for another pkmcal run), and wait
    until no other LinuxCNC holds :data:`LINUXCNC_LOCK` (a lock file with no LinuxCNC
    process running is stale and does not count)."""
    fd = os.open(LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o666)
    try:
        deadline = time.monotonic() + wait
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise PkmcalError(f"another pkmcal LinuxCNC run held {LOCK_FILE} for {wait:g} s; try again when "
                                      "it has finished") from None
                time.sleep(0.2)
        while os.path.exists(LINUXCNC_LOCK) and _linuxcnc_processes():
            if time.monotonic() > deadline:
                raise PkmcalError(f"another LinuxCNC is running on this host ({LINUXCNC_LOCK} exists; LinuxCNC runs "
                                  "one instance per host): stop it, or remove the file if no LinuxCNC runs")
            time.sleep(0.2)
        yield
    finally:
        os.close(fd)      # releases the lock


def _program_units(mm_per_unit: float) -> tuple[str, float]:
    """``(G-code, program units per controller unit)`` of the MDI moves: G20 (inch) on an inch
    machine, else G21 (mm), so that the numbers sent are in the machine's own unit."""
    if mm_per_unit == 25.4:
        return "G20", 1.0
    if mm_per_unit == 1.0:
        return "G21", 1.0
    raise PkmcalError(f"LinuxCNC runs in mm or inch ([TRAJ] LINEAR_UNITS); these files are in units of "
                      f"{mm_per_unit:g} mm")


def stop_tolerance(mm_per_unit: float) -> float:
    """Where LinuxCNC's joint planner stops (controller units): within ``TINY_DP = 0.001 a T²``
    of its target, a the joint's acceleration limit and T the servo period (LinuxCNC
    ``src/emc/motion/simple_tp.c``, ``simple_tp_update``; homing's last move and joint jogs use
    this planner)."""
    return 0.001 * (_ACCEL_MM / mm_per_unit) * _SERVO_PERIOD ** 2


#: Process names of a running LinuxCNC (its start script, server, task and realtime host).
_LINUXCNC_PROGRAMS = ("linuxcnc", "linuxcncsvr", "milltask", "rtapi_app")


def _linuxcnc_processes() -> list[int]:
    """Pids of running LinuxCNC programs (read from /proc, only to know whether LinuxCNC's
    lock file is live: a lock left by a crashed run has none, and LinuxCNC's start script
    removes it itself)."""
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/comm") as fh:
                    if fh.read().strip() in _LINUXCNC_PROGRAMS:
                        pids.append(int(entry))
            except OSError:
                continue
    return pids


def _unprivileged_uid() -> int:
    try:
        return pwd.getpwnam("nobody").pw_uid
    except KeyError:
        return 65534


def run_linuxcnc(files: ControllerFiles, poses: np.ndarray, jog_targets: np.ndarray, *,
                 timeout: float = 300.0, name: str = "pkmcal-check") -> LinuxcncRun:
    """Start LinuxCNC on :func:`headless_config` of ``files``, home, move to ``poses`` (N, 6)
    in world mode and jog the joints to ``jog_targets`` (M, 6) in joint mode (controller
    units, degrees), and return what it reported. Serialised per host (:func:`host_lock`)."""
    require_linuxcnc()
    poses = np.asarray(poses, dtype=float).reshape(-1, 6)
    jog_targets = np.asarray(jog_targets, dtype=float).reshape(-1, 6)
    start = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="pkmcal-lcnc-") as work, host_lock():
        display = os.path.join(work, "pkmcal-display")
        shutil.copyfile(DISPLAY_PROGRAM, display)
        os.chmod(display, 0o755)
        ini_path = os.path.join(work, "machine.ini")
        Path(ini_path).write_text(headless_config(files, display, name))
        Path(work, "kinematics.hal").write_text(files.hal)
        Path(work, "pkmcal.tbl").write_text("")
        Path(work, "pkmcal.var").write_text("")
        unit_code, program_per_unit = _program_units(files.mm_per_unit)
        speed = _SPEED_MM / files.mm_per_unit
        program = poses.copy()
        program[:, :3] *= program_per_unit
        Path(work, JOB_FILE).write_text(json.dumps({
            "poses": program.tolist(), "joint_targets": jog_targets.tolist(), "units_code": unit_code,
            "jog_velocity": speed, "timeout": 60.0}))
        env = {k: v for k, v in os.environ.items() if k != "DISPLAY"}
        fifo = tempfile.mkdtemp(prefix="pkmcal-rtapi-", dir="/tmp")   # short: a socket path lives there
        try:
            if os.geteuid() == 0:
                uid = _unprivileged_uid()
                os.chown(fifo, uid, -1)
                env["RTAPI_UID"] = str(uid)
            env["RTAPI_FIFO_PATH"] = os.path.join(fifo, "rtapi")    # the socket itself, not its directory
            log, ok = _run_until_display_exits(["linuxcnc", "-r", ini_path], work, env, timeout)
        finally:
            shutil.rmtree(fifo, ignore_errors=True)
        result_path = Path(work, RESULT_FILE)
        if not result_path.exists():
            why = "timed out" if not ok else "no result"
            raise PkmcalError(f"LinuxCNC did not run the DISPLAY program to the end ({why}); its output ends: "
                              f"{one_line(log.strip()[-400:])}")
        result = json.loads(result_path.read_text())
    if result.get("error"):
        raise PkmcalError(f"LinuxCNC run failed: {one_line(result['error'])}; its output ends: "
                          f"{one_line(log.strip()[-300:])}")
    wm, jm = result["world_mode"], result["joint_mode"]

    def arr(rows, key):
        return np.array([r[key] for r in rows], dtype=float).reshape(-1, 6)

    return LinuxcncRun(linear_unit=files.linear_unit, mm_per_unit=files.mm_per_unit,
                       home_joints=np.array(result["home"]["joints"], dtype=float),
                       home_world=np.array(result["home"]["world"], dtype=float),
                       commanded=poses, joints=arr(wm, "joints"), world=arr(wm, "world"),
                       jog_targets=jog_targets, joints_held=arr(jm, "joints"), jog_world=arr(jm, "world"),
                       stop_tolerance=stop_tolerance(files.mm_per_unit), seconds=time.monotonic() - start, log=log)


def _run_until_display_exits(cmd: list[str], work: str, env: dict, timeout: float) -> tuple[str, bool]:
    """Run LinuxCNC's start script to its end; on ``timeout`` stop our DISPLAY program (by
    the pid it wrote), which makes LinuxCNC clean up and exit. ``(output, in time)``."""
    log_path = os.path.join(work, "linuxcnc.log")
    with open(log_path, "wb") as log:
        proc = subprocess.Popen(cmd, cwd=work, env=env, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT)
        in_time = True
        try:
            proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            in_time = False
            pid_file = Path(work, PID_FILE)
            if pid_file.exists():
                with contextlib.suppress(ProcessLookupError, ValueError):
                    os.kill(int(pid_file.read_text()), signal.SIGTERM)
            try:
                proc.wait(timeout=120)
            except subprocess.TimeoutExpired:
                raise PkmcalError(f"LinuxCNC did not shut down after its DISPLAY program was stopped (start script "
                                  f"pid {proc.pid}); stop it by hand, then remove {LINUXCNC_LOCK}") from None
    return Path(log_path).read_text(errors="replace"), in_time


# -- the comparison ------------------------------------------------------------------------

@dataclass(frozen=True)
class LinuxcncCheck:
    """LinuxCNC against pkmcal's model of one machine (mm, degrees; module docstring)."""

    machine: str
    run: LinuxcncRun
    poses: np.ndarray                # (N, 6) commanded poses, mm and rad
    ik_diff: np.ndarray              # (N, 6) LinuxCNC joints − pkmcal strut lengths (mm)
    world_diff: np.ndarray           # (N, 6) LinuxCNC's reported pose − commanded (mm, deg)
    home_joint_diff: np.ndarray      # (6,) LinuxCNC's joints after homing − pkmcal's at the home pose (mm)
    fk_diff: np.ndarray              # (M, 6) LinuxCNC's FK − pkmcal's FK of the joints held (mm, deg)
    fk_bound: np.ndarray             # (M,) 2 ‖J⁻¹‖₂ ‖r‖₂ + rounding: bound on each |fk_diff| row
    fk_residual: np.ndarray          # (M, 6) pkmcal's strut lengths at LinuxCNC's FK pose − the joints held (mm)
    jog_miss: np.ndarray             # (M, 6) joints held − jog targets (mm)
    #: The largest change of the strut lengths at the commanded poses that the export's rounding
    #: of the machine's numbers (to 1 nm) makes, allowed on top of IK_TOLERANCE_MM (mm).
    rounding: float = 0.0

    @property
    def ik_max(self) -> float:
        return float(np.max(np.abs(self.ik_diff)))

    @property
    def fk_max_mm(self) -> float:
        return float(np.max(np.abs(self.fk_diff[:, :3]))) if len(self.fk_diff) else 0.0

    @property
    def fk_max_deg(self) -> float:
        return float(np.max(np.abs(self.fk_diff[:, 3:]))) if len(self.fk_diff) else 0.0

    @property
    def ok(self) -> bool:
        """World mode to :data:`IK_TOLERANCE_MM` plus the export's rounding; homing within the joint planner's stopping
        tolerance of the exported HOME and jogs within twice it of their targets (an
        incremental jog starts from the previous target, not from where the joint stopped);
        joint mode within its bound."""
        stop = self.run.stop_tolerance * self.run.mm_per_unit
        return (self.ik_max <= IK_TOLERANCE_MM + self.rounding and float(np.max(np.abs(self.home_joint_diff))) <= stop
                and (not len(self.jog_miss) or float(np.max(np.abs(self.jog_miss))) <= 2 * stop)
                and bool(np.all(np.abs(self.fk_diff) <= self.fk_bound[:, None])))

    ignored_limits: tuple[str, ...] = ()   # the machine's limits its home violates (not used to pick poses)

    def to_dict(self) -> dict:
        """The figures of :meth:`lines` (mm, degrees), for ``pkmcal check linuxcnc --json``."""
        r = self.run
        stop = r.stop_tolerance * r.mm_per_unit
        return {"machine": self.machine, "linear_unit": r.linear_unit, "seconds": r.seconds, "ok": self.ok,
                "world_mode": {"poses": len(self.poses), "max_joint_diff_mm": self.ik_max,
                               "tolerance_mm": IK_TOLERANCE_MM, "export_rounding_mm": self.rounding},
                "homing": {"max_joint_diff_mm": float(np.max(np.abs(self.home_joint_diff))), "tolerance_mm": stop},
                "joint_mode": {"jogs": len(self.fk_diff), "max_pose_diff_mm": self.fk_max_mm,
                               "max_pose_diff_deg": self.fk_max_deg,
                               "bound": float(np.max(self.fk_bound)) if len(self.fk_bound) else 0.0,
                               "max_jog_miss_mm": float(np.max(np.abs(self.jog_miss))) if len(self.jog_miss) else 0.0,
                               "jog_tolerance_mm": 2 * stop},
                "ignored_limits": list(self.ignored_limits)}

    def lines(self) -> list[str]:
        r = self.run
        stop = r.stop_tolerance * r.mm_per_unit
        notes = ([f"note: the home pose violates the machine's {', '.join(self.ignored_limits)} limit(s); the poses "
                  "were chosen without them"] if self.ignored_limits else [])
        return notes + [
            f"LinuxCNC ran machine '{self.machine}' ({r.linear_unit}) in {r.seconds:.1f} s: "
            f"{len(self.poses)} poses by MDI G53 G0, {len(self.fk_diff)} by joint jogs",
            f"world mode: largest |LinuxCNC joint - pkmcal strut length| {self.ik_max:.3g} mm (tolerance "
            f"{IK_TOLERANCE_MM:g} mm + {self.rounding:.3g} mm, what rounding the numbers to 1 nm changes)",
            f"homing: joints within {float(np.max(np.abs(self.home_joint_diff))):.3g} mm of the exported HOME "
            f"(LinuxCNC's joint planner stops within {stop:.3g} mm)",
            f"joint mode: largest |LinuxCNC pose - pkmcal fk| of the joints held {self.fk_max_mm:.3g} mm, "
            f"{self.fk_max_deg:.3g} deg (bound from genhexkins' convergence criterion "
            f"{float(np.max(self.fk_bound)) if len(self.fk_bound) else 0.0:.3g}); joints stopped within "
            f"{float(np.max(np.abs(self.jog_miss))) if len(self.jog_miss) else 0.0:.3g} mm of the jog targets "
            f"(tolerance {2 * stop:.3g} mm)",
        ]


#: Inner margin of the poses sent to LinuxCNC, as a fraction of each joint's range: a
#: commanded pose keeps its struts this far inside the exported joint limits.
POSE_MARGIN = 0.02
#: Points per straight move checked against the joint limits (LinuxCNC interpolates
#: X Y Z A B C linearly and stops with "Exceeded soft limit" if a strut leaves its range).
PATH_SAMPLES = 64


def _within(machine, poses: np.ndarray, limits: np.ndarray, margin: float = 0.0,
            ignore: tuple[str, ...] = ()) -> np.ndarray:
    """Poses whose strut lengths lie within ``limits`` (6, 2) mm, ``margin`` of each range
    inside, and that pass the machine's own limits (joint tilts, leg collisions, singularity
    margin: its workspace) except those named in ``ignore``."""
    L = machine.leg_lengths(poses)
    pad = margin * (limits[:, 1] - limits[:, 0])
    ok = np.all((L >= limits[:, 0] + pad) & (L <= limits[:, 1] - pad), axis=1)
    for name, bad in machine.check_limits(poses).violations.items():
        if name not in ignore:
            ok &= ~np.asarray(bad, dtype=bool)
    return ok


def limits_violated_at_home(machine) -> tuple[str, ...]:
    """The machine's limits its home pose violates (a calibrated machine's joints moved, say
    into a leg collision): they cannot bound the poses sent to LinuxCNC, which starts at home,
    so they are ignored there (and listed in :meth:`LinuxcncCheck.lines`)."""
    report = machine.check_limits(np.asarray(machine.home_pose, dtype=float)[None])
    return tuple(name for name, bad in report.violations.items() if np.asarray(bad)[0])


def workspace_poses(machine, n: int, seed: int = 0, joint_limits: np.ndarray | None = None) -> np.ndarray:
    """``n`` poses (mm, rad) across the machine's workspace box (``workspace_box()``: home ±
    the stroke-scaled box, or the machine's own) with their struts :data:`POSE_MARGIN` inside
    ``joint_limits`` (6, 2) mm (default: the machine's stroke), within the machine's own
    limits (but those its home violates, :func:`limits_violated_at_home`): the 64 corners of the largest
    box home ± t·(half-widths) whose corners all pass (t bisected), then uniform random poses
    of the whole box that pass, in a random order."""
    from pkmcal.planning.candidates import corner_poses, random_poses

    limits = _joint_limits_mm(machine, joint_limits)
    ignore = limits_violated_at_home(machine)
    rng = np.random.default_rng(seed)
    box = np.asarray(machine.workspace_box(), dtype=float)
    home = np.asarray(machine.home_pose, dtype=float)
    if not _within(machine, home[None], limits, ignore=ignore)[0]:
        raise PkmcalError(f"machine '{machine.name}': the home pose is outside the joint limits (or too near a "
                          "singularity); LinuxCNC homes there: fix the home pose or the joint limits first")
    lo, hi = 0.0, 1.0
    for _ in range(30):                 # bisection on the corners' scale
        t = 0.5 * (lo + hi)
        if np.all(_within(machine, corner_poses(home[:, None] + t * (box - home[:, None])), limits, POSE_MARGIN,
                          ignore)):
            lo = t
        else:
            hi = t
    corners = corner_poses(home[:, None] + lo * (box - home[:, None]))
    picked = corners[rng.permutation(len(corners))[: n // 2]] if lo > 0 else np.empty((0, 6))
    # random poses in the box scaled about home to 4 times the corners' scale: a declared box
    # mostly beyond reach (LinuxCNC's sample imports its [AXIS_*] limits of ±1000 inch) would
    # give almost none within the limits
    sampled = home[:, None] + min(1.0, 4.0 * lo) * (box - home[:, None]) if lo > 0 else box
    for _ in range(100):
        if len(picked) >= n:
            break
        cand = random_poses(sampled, 8 * n, rng)
        picked = np.concatenate([picked, cand[_within(machine, cand, limits, POSE_MARGIN, ignore)]])
    if len(picked) < n:
        raise PkmcalError(f"machine '{machine.name}': fewer than {n} poses of its workspace box are within its "
                          "joint limits; check the joint limits and the workspace")
    return picked[:n][rng.permutation(n)]


def route(machine, poses: np.ndarray, joint_limits: np.ndarray | None = None, n: int | None = None) -> np.ndarray:
    """The first ``n`` (default all) of the poses LinuxCNC can move through from home by
    straight moves (G0 interpolates X Y Z A B C linearly), in their order: a move whose
    struts would leave the joint limits (or the machine's limits) on the way, checked at
    :data:`PATH_SAMPLES` points, goes through the home pose instead, which is then one more
    commanded pose; a pose that cannot be reached either way is left out."""
    limits = _joint_limits_mm(machine, joint_limits)
    ignore = limits_violated_at_home(machine)
    home = np.asarray(machine.home_pose, dtype=float)
    t = np.linspace(0.0, 1.0, PATH_SAMPLES)[:, None]

    def clear(a, b):
        return bool(np.all(_within(machine, a + t * (b - a), limits, ignore=ignore)))

    out, here, reached = [], home, 0
    for p in poses:
        if n is not None and reached >= n:
            break
        reached += 1
        if clear(here, p):
            out.append(p)
            here = p
        elif clear(here, home) and clear(home, p):
            out += [home, p]
            here = p
        else:
            reached -= 1
    if n is not None and reached < n:
        raise PkmcalError(f"machine '{machine.name}': only {reached} of the {len(poses)} poses can be reached from "
                          "home by straight moves within the joint limits; check the joint limits and the workspace")
    return np.array(out, dtype=float).reshape(-1, 6)


def _joint_limits_mm(machine, joint_limits: np.ndarray | None) -> np.ndarray:
    if joint_limits is not None:
        return np.asarray(joint_limits, dtype=float).reshape(6, 2)
    g = np.asarray(machine.gains, dtype=float)[:, None]
    return machine.offset[:, None] + g * machine.stroke


def machine_files(machine, linear_unit: str | None = None) -> ControllerFiles:
    """The export of ``machine`` (:func:`pkmcal.io.export_linuxcnc.linuxcnc_hal` and
    :func:`~pkmcal.io.export_linuxcnc.linuxcnc_ini`) as :class:`ControllerFiles`."""
    from pkmcal.io.export_linuxcnc import linuxcnc_hal, linuxcnc_ini

    kw = {} if linear_unit is None else {"linear_unit": linear_unit}
    return controller_files(linuxcnc_hal(machine, **kw), linuxcnc_ini(machine, **kw))


def compare(machine, run: LinuxcncRun) -> LinuxcncCheck:
    """:class:`LinuxcncCheck` of a run against ``machine`` (the model the files came from)."""
    from pkmcal.conventions import poses_from_file_units, poses_to_file_units

    u = run.mm_per_unit

    def to_internal(p):
        p = np.array(p, dtype=float).reshape(-1, 6)
        p[:, :3] *= u
        return poses_from_file_units(p)

    poses = to_internal(run.commanded)
    ik_diff = run.joints * u - machine.leg_lengths(poses)
    world_diff = run.world - run.commanded
    home_joint_diff = run.home_joints * u - machine.leg_lengths(machine.home_pose)[0]
    held = run.joints_held * u
    lc_fk = to_internal(run.jog_world)
    fk = machine.fk_lengths(held, guess=lc_fk, polish=1)
    if not np.all(fk.converged):
        raise PkmcalError(f"machine '{machine.name}': pkmcal's FK did not converge at the joints LinuxCNC holds")
    fk_file = poses_to_file_units(fk.poses)
    lc_file = np.array(run.jog_world, dtype=float)
    lc_file[:, :3] *= u
    fk_diff = lc_file - fk_file
    residual = machine.leg_lengths(lc_fk) - held
    g = np.asarray(machine.gains, dtype=float)
    J = g[None, :, None] * machine.actuator_pose_jacobian(fk.poses)           # ∂L/∂pose, (M, 6, 6)
    inv_norm = 1.0 / np.linalg.svd(J, compute_uv=False)[:, -1]                 # ‖J⁻¹‖₂
    scale = np.max(np.abs(held), axis=1)
    bound_internal = inv_norm * (2.0 * np.linalg.norm(residual, axis=1) + 64 * np.finfo(float).eps * scale)
    # one bound in mm for x, y, z and its radians in degrees for a, b, c: the larger of the two
    fk_bound = np.maximum(bound_internal, np.rad2deg(bound_internal))
    from pkmcal.io.export_linuxcnc import EXPORT_UNITS, rounded_machine

    unit = next((n for n, f in EXPORT_UNITS.items() if f == u), None)
    rounding = 0.0 if unit is None else float(np.max(np.abs(rounded_machine(machine, unit).leg_lengths(poses)
                                                              - machine.leg_lengths(poses))))
    return LinuxcncCheck(machine=machine.name, run=run, poses=poses, ik_diff=ik_diff, world_diff=world_diff,
                         home_joint_diff=home_joint_diff, fk_diff=fk_diff, fk_bound=fk_bound, fk_residual=residual,
                         jog_miss=(run.joints_held - run.jog_targets) * u, rounding=rounding,
                         ignored_limits=limits_violated_at_home(machine))


def check_machine(machine, files: ControllerFiles | None = None, *, n_poses: int = 24, seed: int = 0,
                  timeout: float = 300.0) -> LinuxcncCheck:
    """Run ``files`` (default: ``machine``'s export) through LinuxCNC on ``n_poses`` poses
    across the workspace in world mode and as many in joint mode (jogs to the strut lengths
    of other poses), and compare with ``machine``."""
    from pkmcal.conventions import poses_to_file_units
    from pkmcal.io.export_linuxcnc import check_hexapod

    check_hexapod(machine)
    files = machine_files(machine) if files is None else files
    u = files.mm_per_unit
    limits = files.joint_limits_mm()
    candidates = workspace_poses(machine, 4 * n_poses, seed, limits)
    world = poses_to_file_units(route(machine, candidates[: 3 * n_poses], limits, n_poses))
    world[:, :3] /= u
    targets = machine.leg_lengths(candidates[3 * n_poses:]) / u
    run = run_linuxcnc(files, world, targets, timeout=timeout, name=machine.name)
    return compare(machine, run)


__all__ = ["ControllerFiles", "LinuxcncCheck", "LinuxcncMissing", "LinuxcncRun", "check_machine", "compare",
           "controller_files", "headless_config", "host_lock", "machine_files", "missing_reason",
           "require_linuxcnc", "run_linuxcnc", "workspace_poses"]
