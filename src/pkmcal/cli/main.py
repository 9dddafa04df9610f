"""Entry point of the ``pkmcal`` command.

Every sub-command lives in its own module under :mod:`pkmcal.cli` and is listed in
:data:`COMMANDS`; a command's module is imported only when that command runs (or its own
``--help`` is asked), so ``pkmcal --help`` starts without NumPy, SciPy, numba or pydantic
(``benchmarks/cli_startup.py``). User errors (:class:`pkmcal.errors.PkmcalError`) are
printed as one line on stderr and exit with code 2, without a traceback; anything else is a
bug and keeps its traceback.
"""

from __future__ import annotations

import importlib
import sys

import click

from pkmcal import __version__
from pkmcal.errors import PkmcalError

#: Command name → (module, click command object in it, the summary ``pkmcal --help`` shows).
#: The summary is the first line of the command's own help; ``tests/test_cli_main.py``
#: checks that the two agree, so that the listing never needs to import a command.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "machines": ("pkmcal.cli.machines_cmd", "machines",
                 "List the built-in machines (usable by name wherever a machine file is accepted)."),
    "info": ("pkmcal.cli.info_cmd", "info_cmd",
             "Describe MACHINE (default: stewart-prototype): summary, workspace, IK→FK round trip."),
    "ik": ("pkmcal.cli.kinematics_cmds", "ik_cmd",
           "Inverse kinematics: leg lengths and readings of the poses in POSES.csv."),
    "fk": ("pkmcal.cli.kinematics_cmds", "fk_cmd",
           "Forward kinematics: the poses that give the readings in LEGS.csv."),
    "plan": ("pkmcal.cli.plan_cmds", "plan_cmd",
             "Choose N poses of MACHINE to measure with SETUP (paper 2 §4, paper 1 §IV)."),
    "observability": ("pkmcal.cli.plan_cmds", "observability_cmd",
                      "Observability indices O1..O5 of the poses in POSES.csv (columns x,y,z mm, a,b,c deg)."),
    "simulate": ("pkmcal.cli.campaign_cmds", "simulate_cmd",
                 "Simulate measuring POSES.csv on a real machine commanded with the nominal MACHINE."),
    "identifiability": ("pkmcal.cli.identify_cmds", "identifiability_cmd",
                        "Which parameters of MACHINE the SETUP can identify from POSES.csv."),
    "identify": ("pkmcal.cli.identify_cmds", "identify_cmd",
                 "Identify MACHINE's kinematic parameters from MEAS.csv and write CALIBRATED.yaml."),
    "verify": ("pkmcal.cli.campaign_cmds", "verify_cmd",
               "Pose errors of the REAL machine commanded through CALIBRATED (and NOMINAL) on held-out poses."),
    "export": ("pkmcal.cli.export_cmd", "export_cmd",
               "Export the machine in CALIBRATED.yaml (a machine file or built-in name) for a controller."),
    "demo": ("pkmcal.cli.demo_cmd", "demo",
             "Calibrate the built-in prototype end to end on a simulated 'real' machine."),
    "reproduce": ("pkmcal.cli.reproduce_cmd", "reproduce",
                  "Regenerate paper table NAME with our numbers beside the published ones."),
    "study": ("pkmcal.cli.study_cmd", "study",
              "Run the Monte Carlo study STUDY.yaml (plan, simulate, identify, verify per trial) into RESULTS/."),
}


#: Key of the command line's arguments in the root ``click.Context.meta`` (for records of
#: how a file was made, :mod:`pkmcal.cli.provenance`).
ARGV_KEY = "pkmcal.argv"


class PkmcalGroup(click.Group):
    """The ``pkmcal`` group: commands from :data:`COMMANDS`, imported on first use, and
    :class:`PkmcalError` turned into one stderr line and exit code 2."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        ctx.meta[ARGV_KEY] = list(args)
        return super().parse_args(ctx, args)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        entry = COMMANDS.get(name)
        if entry is None:
            return None
        module, attr, _ = entry
        return getattr(importlib.import_module(module), attr)

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        """The command list with the full summaries of :data:`COMMANDS` (no import, no
        truncation)."""
        with formatter.section("Commands"):
            formatter.write_dl([(name, summary) for name, (_, _, summary) in COMMANDS.items()])

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except PkmcalError as exc:
            click.echo(f"pkmcal: error: {exc}", err=True)
            sys.exit(exc.exit_code)


#: Examples of ``pkmcal --help`` (each command's ``--help`` has its own; all are run by
#: ``tests/test_cli_examples.py``).
EXAMPLES = (
    "pkmcal machines",
    "pkmcal demo",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n 45 --seed 1 -o poses.csv",
    "pkmcal simulate stewart-prototype --real stewart-prototype-real --setup indicators-prototype --poses poses.csv "
    "--seed 2 -o meas.csv",
    "pkmcal identify stewart-prototype meas.csv --setup indicators-prototype -o calibrated.yaml",
    "pkmcal export calibrated.yaml --format linuxcnc -o kinematics.hal",
)


@click.group(cls=PkmcalGroup, context_settings={"help_option_names": ["-h", "--help"]},
             epilog="\b\nExamples:\n" + "\n".join(f"  {c}" for c in EXAMPLES) + "\n\nRun 'pkmcal COMMAND --help' for "
                    "a command's options and examples.")
@click.version_option(__version__, prog_name="pkmcal")
def cli() -> None:
    """Calibrate parallel kinematic machines (hexapods, redundantly actuated PKMs).

    Units: mm; angles in degrees on the command line and in files. Pose = x y z a b c with
    R = Rz(c)·Ry(b)·Rx(a) (roll, pitch, yaw about the fixed base axes).
    """


def main() -> None:
    cli(prog_name="pkmcal")


if __name__ == "__main__":
    main()
