"""Options every command spells the same way: ``-o/--output``, ``-q/--quiet``, and the old
spellings kept working with a deprecation note.

* ``-o FILE``: the command's main output (a CSV, a table, JSON, a machine file) goes to FILE,
  written atomically and never over one of the command's inputs; without ``-o``, or with
  ``-o -``, it goes to standard output (every command with one main output; ``plan``,
  ``identify`` and ``reproduce`` included) and the human summary to standard error, so the
  output stays machine-readable. ``demo`` and ``study`` write a folder: ``-o DIR``, and
  ``-o -`` is refused (:func:`check_output_folder`).
* ``--units-comment``: a written CSV starts with its units line and comments (default: a
  plain CSV that pandas and csv read with their defaults).
* ``-q/--quiet``: no progress bar (bars appear only on a terminal anyway, see
  :mod:`pkmcal.progress`) and no progress notes; accepted by every command that prints
  figures, also by those that show no progress (:func:`quiet_accepted`).
* Old spellings (issue 27 item 3; the table of ``docs/options.md``) keep working, hidden from
  ``--help``: :class:`Option` takes them as ``old=("--heldout",)``, the old positional poses
  file is a :class:`DeprecatedArgument` read by :func:`poses_file`, the old ``--poses N`` is
  read by :func:`count_or_poses_file`. Each use warns through :func:`deprecated`, a
  :class:`pkmcal.errors.PkmcalWarning` that the command line prints as one
  ``pkmcal: warning: --old is deprecated; use --new`` line on standard error.
"""

from __future__ import annotations

import os
import warnings

import click

from pkmcal.errors import PkmcalError, PkmcalWarning
from pkmcal.io.atomic import atomic_write_text, check_output_path

#: ``-o -``: standard output.
STDOUT = "-"


class Option(click.Option):
    """A click option that also takes its old spellings ``old`` (``--heldout`` for
    ``--held-out``): they give the same value, are not shown in ``--help``, and each use warns
    (:func:`deprecated`). The old spellings are registered with the parser under their own
    destination, so that :meth:`consume_value` knows which spelling was given; giving both is
    a usage error. The command function gets the value under the option's one name."""

    def __init__(self, *args, old: tuple[str, ...] | list[str] = (), **kwargs):
        super().__init__(*args, **kwargs)
        self.old_opts = tuple(old)
        if self.old_opts and self.count:
            raise TypeError("old spellings of a counting option are not supported")

    def _old_dest(self, opt: str) -> str:
        return f"{self.name} (old {opt})"

    def add_to_parser(self, parser, ctx: click.Context) -> None:
        super().add_to_parser(parser, ctx)
        base = "append" if self.multiple else "store"
        for opt in self.old_opts:
            if self.is_flag:
                parser.add_option(obj=self, opts=[opt], dest=self._old_dest(opt), action=f"{base}_const",
                                  const=self.flag_value)
            else:
                parser.add_option(obj=self, opts=[opt], dest=self._old_dest(opt), action=base, nargs=self.nargs)

    def consume_value(self, ctx: click.Context, opts):
        used = [opt for opt in self.old_opts if self._old_dest(opt) in opts]
        if used:
            new = max(self.opts, key=len)
            given = [new] * (self.name in opts) + used
            if len(given) > 1 and not self.multiple:
                raise click.UsageError(f"{' and '.join(given)} are the same option; give it once, as {new}", ctx)
            merged = [] if self.multiple else None
            for key in ([self.name] if self.name in opts else []) + [self._old_dest(opt) for opt in used]:
                merged = merged + list(opts[key]) if self.multiple else opts[key]
            for opt in used:
                deprecated(opt, new)
            opts = {**opts, self.name: merged}
        return super().consume_value(ctx, opts)


def option(*param_decls: str, old: tuple[str, ...] = (), **kwargs):
    """``click.option`` with old spellings (:class:`Option`)."""
    return click.option(*param_decls, cls=Option, old=old, **kwargs)


def output_option(metavar: str, what: str, *, default: str | None = None):
    """``-o/--output`` for a command whose main output is ``what`` (a file path; nothing or
    ``-`` = standard output). ``default`` is what the command gets without ``-o`` (None, or
    :data:`STDOUT` for a command whose body reads ``-``)."""
    return click.option("-o", "--output", "output", metavar=metavar, default=default,
                  help=f"{what} (default: standard output; '-' = standard output).")


def check_output_folder(folder: str, what: str) -> None:
    """``-o`` of a command whose output is a folder of files (``demo``, ``study``): ``-``
    (standard output) cannot hold one."""
    if folder == STDOUT:
        raise PkmcalError(f"-o -: {what} is a folder of files, which standard output cannot hold; give a folder name")


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


QUIET_HELP = ("No progress bar or progress notes (a bar is shown only when standard output and standard error "
              "are terminals).")


def quiet_option(command):
    """``-q/--quiet``: no progress bar and no progress notes."""
    return click.option("-q", "--quiet", is_flag=True, help=QUIET_HELP)(command)


def quiet_accepted(command):
    """``-q/--quiet`` on a command that shows no progress bar or progress notes: accepted (so
    that a script can pass ``-q`` to every command that prints figures) and not passed to the
    command function."""
    return click.option("-q", "--quiet", is_flag=True, expose_value=False,
                        help=QUIET_HELP + " This command shows none.")(command)


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


def deprecated(old: str, new: str) -> None:
    """Warn that the spelling ``old`` is deprecated in favour of ``new``: a
    :class:`PkmcalWarning`, printed by the command line as one
    ``pkmcal: warning: OLD is deprecated; use NEW`` line (:mod:`pkmcal.cli.main`)."""
    warnings.warn(f"{old} is deprecated; use {new}", PkmcalWarning, stacklevel=2)


def count_or_poses_file(poses: str | None, n_poses: int | None, default: int) -> tuple[int, str | None]:
    """``(count, file)`` from ``--n-poses N`` and ``--poses FILE``: ``--poses`` is a poses
    file everywhere; the old ``--poses N`` (a count, when no file of that name exists) still
    works, with a deprecation note."""
    if poses is not None and n_poses is not None:
        raise PkmcalError("give --poses FILE (poses to use) or --n-poses N (how many), not both")
    if poses is not None and poses.strip().isdigit() and not os.path.exists(poses):
        deprecated(f"'--poses {poses}' as a number of poses", f"'--n-poses {poses}' (--poses takes a poses file)")
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
        deprecated(f"'pkmcal {command} MACHINE {positional}' (the poses file as an argument)", f"'--poses {positional}'")
        return positional
    if option is None:
        raise click.UsageError("Missing option '--poses'.")
    return option


__all__ = ["DeprecatedArgument", "Option", "STDOUT", "check_output", "check_output_folder", "count_or_poses_file", "deprecated", "emit",
           "examples", "option", "output_option", "poses_file", "quiet_accepted", "quiet_option", "summary_echo",
           "to_stdout", "units_comment_option"]
