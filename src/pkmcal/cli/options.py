"""Options every command spells the same way: ``-o/--output``, ``-q/--quiet``, and the old
spellings kept working with a deprecation note.

* ``-o FILE``: the command's main output (a CSV, a table, JSON, a machine file) goes to FILE,
  written atomically and never over one of the command's inputs; without ``-o``, or with
  ``-o -``, it goes to standard output (commands with a natural stdout; ``plan``,
  ``identify`` and ``reproduce`` included) and the human summary to standard error, so the
  output stays machine-readable.
* ``--units-comment``: a written CSV starts with its units line and comments (default: a
  plain CSV that pandas and csv read with their defaults).
* ``-q/--quiet``: no progress bar (bars appear only on a terminal anyway, see
  :mod:`pkmcal.progress`) and no progress notes.
* Deprecated spellings print one ``pkmcal: deprecated: ...`` line on standard error and
  work as before.
"""

from __future__ import annotations

import os

import click

from pkmcal.errors import PkmcalError
from pkmcal.io.atomic import atomic_write_text, check_output_path

#: ``-o -``: standard output.
STDOUT = "-"


def output_option(metavar: str, what: str, *, stdout: bool = True):
    """``-o/--output`` for a command whose main output is ``what`` (a file path; ``-`` or,
    with ``stdout``, nothing = standard output)."""
    text = f"{what} (default: standard output; '-' = standard output)." if stdout else f"{what} ('-' = standard output)."
    return click.option("-o", "--output", metavar=metavar, required=not stdout, help=text)


def to_stdout(output: str | None) -> bool:
    """Whether the main output goes to standard output (no ``-o`` or ``-o -``)."""
    return output is None or output == STDOUT


def check_output(output: str | None, inputs) -> None:
    """Refuse ``-o`` naming an input, a folder, or nothing; standard output is always fine."""
    if to_stdout(output):
        return
    if not str(output).strip():
        raise PkmcalError("-o '': give an output file name, or '-' for standard output")
    if os.path.isdir(output):
        raise PkmcalError(f"-o '{output}' is a folder; give a file name")
    check_output_path(output, inputs)


def emit(text: str, output: str | None) -> None:
    """Write the main output ``text`` to standard output or atomically to the file."""
    if to_stdout(output):
        click.echo(text, nl=False)
    else:
        atomic_write_text(output, text)


def summary_echo(output: str | None):
    """``click.echo`` for the human summary: standard error when the main output is on
    standard output (it stays machine-readable), else standard output."""
    err = to_stdout(output)
    return lambda message="": click.echo(message, err=err)


def quiet_option(command):
    """``-q/--quiet``: no progress bar and no progress notes."""
    return click.option("-q", "--quiet", is_flag=True,
                        help="No progress bar or progress notes (a bar is shown only when standard output "
                             "and standard error are terminals).")(command)


def units_comment_option(command):
    """``--units-comment``: begin a written CSV with its ``# units:`` line and the comment lines
    saying how it was made. Off by default, so that every CSV pkmcal writes is a plain table
    that ``pandas.read_csv`` and ``csv.DictReader`` read with their defaults
    (:func:`pkmcal.io.tables.format_table`); pkmcal reads both."""
    return click.option("--units-comment", is_flag=True,
                        help="Begin the CSV with '# units: length=mm, angle=deg' and comment lines on how it was "
                             "made (pkmcal reads them; pandas/csv then need comment='#'). Default: a plain CSV, "
                             "in mm and degrees.")(command)


def examples(*commands: str) -> str:
    """The epilog of a command's ``--help``: an Examples section, one command line each (not
    rewrapped; ``tests/cli/test_examples.py`` runs every one of them)."""
    return "\b\nExamples:\n" + "\n".join(f"  {c}" for c in commands)


def deprecated(message: str) -> None:
    """One ``pkmcal: deprecated:`` line on standard error."""
    click.echo(f"pkmcal: deprecated: {message}", err=True)


def count_or_poses_file(poses: str | None, n_poses: int | None, default: int) -> tuple[int, str | None]:
    """``(count, file)`` from ``--n-poses N`` and ``--poses FILE``: ``--poses`` is a poses
    file everywhere; the old ``--poses N`` (a count, when no file of that name exists) still
    works, with a deprecation note."""
    if poses is not None and n_poses is not None:
        raise PkmcalError("give --poses FILE (poses to use) or --n-poses N (how many), not both")
    if poses is not None and poses.strip().isdigit() and not os.path.exists(poses):
        deprecated(f"'--poses {poses}' as a number of poses; use '--n-poses {poses}' (--poses takes a poses file)")
        n = int(poses)
        if n < 1:
            raise PkmcalError(f"--n-poses {n}: give at least 1")
        return n, None
    return (default if n_poses is None else n_poses), poses


class DeprecatedArgument(click.Argument):
    """A positional argument kept for an old spelling: accepted, not shown in the usage line."""

    def get_usage_pieces(self, ctx: click.Context) -> list[str]:
        return []


def poses_file(option: str | None, positional: str | None, command: str) -> str:
    """The poses file of ``--poses FILE``, or of the old positional spelling (deprecated)."""
    if option is not None and positional is not None:
        raise PkmcalError(f"two poses files ('{positional}' and --poses '{option}'); give one with --poses")
    if positional is not None:
        deprecated(f"'pkmcal {command} MACHINE {positional}'; use '--poses {positional}'")
        return positional
    if option is None:
        raise click.UsageError("Missing option '--poses'.")
    return option


__all__ = ["DeprecatedArgument", "STDOUT", "check_output", "count_or_poses_file", "deprecated", "emit", "examples",
           "output_option", "poses_file", "quiet_option", "summary_echo", "to_stdout", "units_comment_option"]
