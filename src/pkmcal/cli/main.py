"""Entry point of the ``pkmcal`` command.

Every sub-command lives in its own module under :mod:`pkmcal.cli` and is registered here.
User errors (:class:`pkmcal.errors.PkmcalError`) are printed as one line on stderr and exit
with code 2, without a traceback; anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import sys

import click

from pkmcal import __version__
from pkmcal.errors import PkmcalError


class PkmcalGroup(click.Group):
    """A click group that turns :class:`PkmcalError` into one stderr line and exit code 2."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except PkmcalError as exc:
            click.echo(f"pkmcal: error: {exc}", err=True)
            sys.exit(exc.exit_code)


@click.group(cls=PkmcalGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pkmcal")
def cli() -> None:
    """Calibrate parallel kinematic machines (hexapods, redundantly actuated PKMs).

    Units: mm; angles in degrees on the command line and in files. Pose = x y z a b c with
    R = Rz(c)·Ry(b)·Rx(a) (roll, pitch, yaw about the fixed base axes).
    """


def _register() -> None:
    # One line per command module; each module defines click commands and adds them here.
    from pkmcal.cli import info_cmd, kinematics_cmds, machines_cmd

    machines_cmd.register(cli)
    kinematics_cmds.register(cli)
    info_cmd.register(cli)
    from pkmcal.cli import campaign_cmds
    campaign_cmds.register(cli)
    from pkmcal.cli import demo_cmd
    demo_cmd.register(cli)
    from pkmcal.cli import plan_cmds
    plan_cmds.register(cli)
    from pkmcal.cli import identify_cmds
    identify_cmds.register(cli)
    from pkmcal.cli import export_cmd
    export_cmd.register(cli)
    from pkmcal.cli import reproduce_cmd
    reproduce_cmd.register(cli)
    from pkmcal.cli import study_cmd; study_cmd.register(cli)  # noqa: E702


_register()


def main() -> None:
    cli(prog_name="pkmcal")


if __name__ == "__main__":
    main()
