"""Entry point of the ``pkmcal`` command.

Every sub-command lives in its own module under :mod:`pkmcal.cli` and is listed in
:data:`COMMANDS`; a command's module is imported only when that command runs (or its own
``--help`` is asked), so ``pkmcal --help`` starts without NumPy, SciPy, numba or pydantic
(``benchmarks/cli_startup.py``).

Errors, one line each on stderr, exit code 2, no traceback:

* user errors (:class:`pkmcal.errors.PkmcalError`), with the file each machine named in
  the message came from (:func:`pkmcal.errors.name_sources`);
* click's usage errors (missing argument, bad option value): its message and the usage on
  one line, ``pkmcal: error: Missing argument 'POSES'. (usage: pkmcal ik [OPTIONS] MACHINE
  POSES; see 'pkmcal ik --help')``, instead of click's three-to-four-line block;
* a request too large for the memory (:class:`MemoryError`).

Every message is made one line by construction (:func:`pkmcal.errors.one_line`). NumPy's
runtime warnings (overflow, invalid value) raised while a command runs are collected:
dropped when the command ends in a user error (the error says what is wrong), and on success
printed as one ``pkmcal: warning:`` line each. Anything else is a bug and keeps its
traceback.
"""

from __future__ import annotations

import importlib
import sys
import warnings

import click

from pkmcal import __version__
from pkmcal.errors import PkmcalError, PkmcalWarning, name_sources, one_line, recorded_sources

#: Command name → (module, click command object in it, the summary ``pkmcal --help`` shows).
#: The summary is the first line of the command's own help; ``tests/cli/test_main.py``
#: checks that the two agree, so that the listing never needs to import a command.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "machines": ("pkmcal.cli.machines_cmd", "machines",
                 "List the built-in machines with their kinds (usable by name wherever a machine file is accepted)."),
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
               "Validate CALIBRATED on held-out data: measured (--held-out) or a true machine (--real)."),
    "export": ("pkmcal.cli.export_cmd", "export_cmd",
               "Export the machine in CALIBRATED.yaml (a machine file or built-in name) for a controller."),
    "compensate": ("pkmcal.cli.correct_cmd", "compensate_cmd",
                   "Fit what CALIBRATED leaves on MEAS.csv, keep it only if HELDOUT.csv confirms it."),
    "correct": ("pkmcal.cli.correct_cmd", "correct_cmd",
                "Filter PROGRAM through the calibrated model (plus a correction) for a nominal controller."),
    "import": ("pkmcal.cli.import_cmd", "import_group",
               "Make a machine file from a controller's configuration (LinuxCNC, Klipper, Marlin)."),
    "check": ("pkmcal.cli.check_cmd", "check_group",
              "Run exported files through the installed controller and compare with pkmcal's model."),
    "demo": ("pkmcal.cli.demo_cmd", "demo",
             "Calibrate the built-in prototype end to end on a simulated 'real' machine."),
    "reproduce": ("pkmcal.cli.reproduce_cmd", "reproduce",
                  "Regenerate paper table NAME with our numbers beside the published ones."),
    "history": ("pkmcal.cli.history_cmd", "history_group",
                "Keep every calibration of a fleet and compare them (SQLite database)."),
    "study": ("pkmcal.cli.study_cmd", "study",
              "Run the Monte Carlo study STUDY.yaml (plan, simulate, identify, verify per trial) into RESULTS/."),
}


#: Key of the command line's arguments in the root ``click.Context.meta`` (for records of
#: how a file was made, :mod:`pkmcal.workflow.provenance`).
ARGV_KEY = "pkmcal.argv"


def command_line() -> str | None:
    """``pkmcal ARGS...`` as typed, quoted for a POSIX shell (None outside a ``pkmcal``
    command): the calibration record's ``command`` (:mod:`pkmcal.workflow.record`)."""
    import shlex

    ctx = click.get_current_context(silent=True)
    argv = None if ctx is None else ctx.find_root().meta.get(ARGV_KEY)
    return None if argv is None else shlex.join(["pkmcal", *argv])


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
        with recorded_sources() as sources, warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", RuntimeWarning)
            warnings.simplefilter("always", PkmcalWarning)
            try:
                result = super().invoke(ctx)
            except PkmcalError as exc:
                # the input warnings that may explain the error (numerical ones would only be noise)
                _report_warnings([w for w in caught if issubclass(w.category, PkmcalWarning)
                                  and str(w.message) not in str(exc)])
                _error_line(name_sources(str(exc), sources))
                sys.exit(exc.exit_code)
            except click.UsageError:
                # an old spelling's note (pkmcal.cli.options.deprecated) before the usage error
                _report_warnings([w for w in caught if issubclass(w.category, PkmcalWarning)])
                raise
            except MemoryError:
                _error_line("not enough memory for this request; ask for fewer poses, candidates or samples")
                sys.exit(PkmcalError.exit_code)
        _report_warnings(caught)
        return result

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        """click's ``main``, with its usage errors printed on one line (module docstring)."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()  # 'pkmcal' alone: the help, as click prints it
            sys.exit(exc.exit_code)
        except click.UsageError as exc:
            usage = ""
            if exc.ctx is not None:
                path = exc.ctx.command_path
                pieces = " ".join(exc.ctx.command.collect_usage_pieces(exc.ctx))
                usage = f" (usage: {path} {pieces}; see '{path} --help')"
            _error_line(exc.format_message() + usage)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            _error_line(exc.format_message())
            sys.exit(exc.exit_code)
        except click.Abort:
            _error_line("aborted")
            sys.exit(1)
        sys.exit(rv if isinstance(rv, int) else 0)


def _error_line(message: str) -> None:
    click.echo(f"pkmcal: error: {one_line(message)}", err=True)


def _report_warnings(caught: list[warnings.WarningMessage]) -> None:
    """Each distinct RuntimeWarning and :class:`PkmcalWarning` as one ``pkmcal: warning:``
    line; other warnings as Python shows them."""
    seen: set[str] = set()
    for w in caught:
        if issubclass(w.category, PkmcalWarning):
            text = one_line(str(w.message))
            if text not in seen:
                seen.add(text)
                click.echo(f"pkmcal: warning: {text}", err=True)
        elif issubclass(w.category, RuntimeWarning):
            text = one_line(str(w.message))
            if text not in seen:
                seen.add(text)
                click.echo(f"pkmcal: warning: numerical problem in this computation ({text}); check the inputs "
                           "for extreme values", err=True)
        else:
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)


#: Examples of ``pkmcal --help`` (each command's ``--help`` has its own; all are run by
#: ``tests/cli/test_examples.py``).
EXAMPLES = (
    "pkmcal machines",
    "pkmcal demo",
    "pkmcal plan stewart-prototype --setup indicators-prototype --n-poses 45 --seed 1 -o poses.csv",
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
    from pkmcal.allocator import configure_process_memory

    configure_process_memory()
    cli(prog_name="pkmcal")


if __name__ == "__main__":
    main()
