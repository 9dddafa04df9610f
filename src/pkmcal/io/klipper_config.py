"""Klipper's ``printer.cfg`` read exactly as Klipper reads it, and written back as its
``SAVE_CONFIG`` writes it.

Each rule below is Klipper's own, cited to ``klippy/configfile.py`` (Klipper v0.12.0 of
2023, where the functions are methods of ``PrinterConfig``; in later Klipper they moved to
``ConfigFileReader`` and ``ConfigAutoSave`` with the same behaviour unless stated):

* **The file** (``_read_config_file``): read whole, ``\\r\\n`` turned into ``\\n``.
* **The SAVE_CONFIG block** (``_find_autosave_data``): the block starts at the first exact
  occurrence of the three header lines (:data:`AUTOSAVE_HEADER`, a blank line before them).
  The whole block is ignored — its ``#*#`` lines are then plain comments — when a line
  starting ``#*# `` occurs above the header, when any line after the header (its trailing
  blank lines aside) does not start with ``#*#``, or starts with ``#*#`` followed by
  anything but a space (later Klipper, commit 85ebafd3f of 2024: also when the header
  occurs twice). Klipper logs a warning and runs without the block; pkmcal says so in a
  note (:attr:`KlipperConfig.notes`).
* **Precedence** (``_strip_duplicates``, ``read_main_config``/``load_main_config``): an
  option of the block that is also set in the main file or its includes is commented out,
  so **the main file's value wins**; the rest of the block is read after everything else.
* **Comments** (``_parse_config``): everything from the first ``#`` of a line is dropped
  (also inside a value); then Python's ``RawConfigParser(strict=False,
  inline_comment_prefixes=(';', '#'))`` reads the rest: ``key: value`` or ``key = value``,
  option names lower-cased, section names exactly as written, a section or option given
  twice is merged and the later value wins, indented lines continue a value, ``;`` starts
  a comment at the start of a line or after white space.
* **Includes** (``_parse_config``, ``_resolve_include``): ``[include PATTERN]`` is applied
  where it stands (the lines above it are read first, then the included files, then the
  lines below), PATTERN relative to the including file's directory, a glob whose matches
  are read in sorted order; a pattern without glob characters must name a file, a glob may
  match nothing; an include that includes itself is an error. Includes inside the
  SAVE_CONFIG block are followed by Klipper v0.12 but not by later Klipper (commit
  9d4ab862b): pkmcal refuses them.
* **Writing** (``cmd_SAVE_CONFIG``): the block's sections as Python's ``RawConfigParser.write``
  lays them out (``[section]``, ``key = value``, a blank line between sections; the
  sections already in the block first, in their order, new ones after), each line prefixed
  ``#*# `` and stripped, after the header; every option of the main file (not its
  includes) that the block now sets is commented out with a ``#`` (its continuation lines
  too), and Klipper refuses a block option that an included file sets
  (``_disallow_include_conflicts``). Klipper writes its own numbers with ``%.6f``; pkmcal
  writes the shortest text that reads back as the same double, so the file holds the
  calibration exactly.
"""

from __future__ import annotations

import codecs
import configparser
import glob
import io
import os
import re
from dataclasses import dataclass, field

from pkmcal.errors import InputFileError, PkmcalError

#: klippy/configfile.py ``AUTOSAVE_HEADER``.
AUTOSAVE_HEADER = ("\n#*# <---------------------- SAVE_CONFIG ---------------------->\n"
                   "#*# DO NOT EDIT THIS BLOCK OR BELOW. The contents are auto-generated.\n#*#\n")


@dataclass(frozen=True)
class Option:
    """One option's text as Klipper's parser holds it, and where it was set."""

    value: str
    path: str
    line: int | None


@dataclass
class KlipperConfig:
    """A printer.cfg as Klipper reads it: ``options[(section, option)]`` (option names
    lower-case, section names as written), the files read, and notes for the user."""

    path: str
    options: dict[tuple[str, str], Option]
    sections: list[str]
    #: The files read: the main file and its includes, in reading order.
    files: list[str]
    #: (section, option) of the block that Klipper reads (not commented out).
    from_block: set[tuple[str, str]] = field(default_factory=set)
    notes: list[str] = field(default_factory=list)

    def get(self, section: str, option: str) -> Option | None:
        return self.options.get((section, option.lower()))

    def has_section(self, section: str) -> bool:
        return section in self.sections

    def float(self, section: str, option: str, default: float | None = None, *, above: float | None = None,
              maxval: float | None = None) -> float:
        """Klipper's ``ConfigWrapper.getfloat``: the option's float, ``default`` when it is
        absent (an error without one), ``above``/``maxval`` as Klipper checks them; pkmcal
        also refuses what is not finite."""
        opt = self.get(section, option)
        if opt is None:
            if default is None:
                raise InputFileError(self.path, f"[{section}] has no '{option}'; Klipper needs it (\"Option "
                                     f"'{option}' in section '{section}' must be specified\")")
            return default
        try:
            v = float(opt.value)
        except ValueError:
            raise InputFileError(opt.path, f"[{section}] {option}: expected a number, got '{opt.value}'",
                                 line=opt.line) from None
        if v != v or v in (float("inf"), float("-inf")):
            raise InputFileError(opt.path, f"[{section}] {option}: expected a finite number, got '{opt.value}'",
                                 line=opt.line)
        if above is not None and v <= above:
            raise InputFileError(opt.path, f"[{section}] {option} = {opt.value}: Klipper requires it above "
                                 f"{above:g}", line=opt.line)
        if maxval is not None and v > maxval:
            raise InputFileError(opt.path, f"[{section}] {option} = {opt.value}: Klipper requires it at most "
                                 f"{maxval:g}", line=opt.line)
        return v


def _parser() -> configparser.RawConfigParser:
    # klippy/configfile.py _build_config_wrapper / ConfigFileReader._create_fileconfig
    return configparser.RawConfigParser(strict=False, inline_comment_prefixes=(";", "#"))


def read_text(path: str) -> str:
    """klippy/configfile.py ``_read_config_file``: the whole file as its ``open(filename, 'r')``
    reads it — UTF-8, CR LF and a lone CR as LF (Python's text mode), a byte-order mark kept
    (Klipper's parser then refuses the file: 'File contains no section headers') — through
    :mod:`pkmcal.io.inputs` (regular files only, a byte that is not UTF-8 named with its line)."""
    from pkmcal.io.inputs import decode_utf8, read_input_bytes

    data = read_input_bytes(path, "Klipper config")
    bom = "\ufeff" if data.startswith(codecs.BOM_UTF8) else ""     # decode_utf8 drops it; open() does not
    return bom + decode_utf8(path, data, "Klipper config").replace("\r\n", "\n").replace("\r", "\n")


def find_autosave(data: str) -> tuple[str, str, str | None, int]:
    """klippy/configfile.py ``_find_autosave_data``: (the text Klipper reads as the main
    config, the block without its ``#*# `` prefixes (one empty line first), why the block is
    ignored or None, the file's line number of the block's first line less 2)."""
    regular, autosave, rest = data, "", ""
    pos = data.find(AUTOSAVE_HEADER)
    if pos >= 0:
        regular = data[:pos]
        rest = data[pos + len(AUTOSAVE_HEADER):]
        autosave = rest.strip()
    # the line of the block's first line: the lines above, the header's, the blank ones
    first = regular.count("\n") + AUTOSAVE_HEADER.count("\n") + rest[:len(rest) - len(rest.lstrip())].count("\n")
    if "\n#*# " in regular:
        line = regular.count("\n", 0, regular.find("\n#*# ")) + 2
        return data, "", (f"line {line} starts with '#*# ' above the SAVE_CONFIG header (or the header lines "
                          "were changed)"), 0
    if pos >= 0 and autosave.find(AUTOSAVE_HEADER) >= 0:       # later Klipper (commit 85ebafd3f)
        return data, "", "the SAVE_CONFIG header occurs twice", 0
    out = [""]
    for k, line in enumerate(autosave.split("\n")):
        if (not line.startswith("#*#") or (len(line) >= 4 and not line.startswith("#*# "))) and autosave:
            return data, "", (f"line {first + k} follows the SAVE_CONFIG header without '#*# ' (Klipper reads "
                              "no line of a block that anything follows)"), 0
        out.append(line[4:])
    out.append("")
    return regular, "\n".join(out), None, first - 2


def _read_buffer(fileconfig, buf: list[tuple[int, str]], path: str, where: dict, order: list[str]) -> None:
    """klippy/configfile.py ``_parse_config_buffer``/``append_fileconfig``: one run of
    lines read by the parser; ``where`` learns (section, option) → (path, line)."""
    if not buf:
        return
    text = "\n".join(t for _, t in buf)
    try:
        fileconfig.read_file(io.StringIO(text), path)
    except configparser.Error as exc:
        lineno = getattr(exc, "lineno", None)
        if lineno is None and getattr(exc, "errors", None):
            lineno = exc.errors[0][0]
        line = buf[lineno - 1][0] if lineno is not None and 0 < lineno <= len(buf) else None
        detail = str(getattr(exc, "message", exc)).split("\n")[0]
        if isinstance(exc, configparser.MissingSectionHeaderError):
            detail = "an option before any [section]"
        elif isinstance(exc, configparser.ParsingError):
            detail = "not a 'key: value' line"
        raise InputFileError(path, f"not a Klipper config: {detail} (Klipper's parser refuses it too)",
                             line=line) from None
    # the line of each option, scanned with the parser's own patterns
    section = None
    optcre = fileconfig._optcre
    for lineno, raw in buf:
        if not raw.strip() or raw[:1].isspace() or raw.strip()[:1] in (";", "#"):
            continue
        head = configparser.RawConfigParser.SECTCRE.match(raw)
        if head:
            section = head.group("header")
            if section not in order:
                order.append(section)
            continue
        mo = optcre.match(raw)
        if mo and section is not None:
            where[(section, fileconfig.optionxform(mo.group("option").rstrip()))] = (path, lineno)


def _parse(data: str, path: str, fileconfig, where: dict, order: list[str], files: list[str],
           visited: set[str], line0: int = 0, includes: bool = True) -> None:
    """klippy/configfile.py ``_parse_config``: lines (comments from ``#`` dropped) in runs
    between ``[include]`` lines, each include read where it stands."""
    real = os.path.abspath(path)
    if real in visited:
        raise InputFileError(path, "[include] loops back to this file (Klipper: 'Recursive include of config "
                             "file')")
    visited.add(real)
    if path not in files:
        files.append(path)
    buf: list[tuple[int, str]] = []
    for k, line in enumerate(data.split("\n"), start=line0 + 1):
        pos = line.find("#")
        if pos >= 0:
            line = line[:pos]
        mo = configparser.RawConfigParser.SECTCRE.match(line)
        header = mo and mo.group("header")
        if header and header.startswith("include "):
            if not includes:
                raise InputFileError(path, "an [include] inside the SAVE_CONFIG block: Klipper v0.12 follows it, "
                                     "later Klipper ignores it; move it above the block", line=k)
            _read_buffer(fileconfig, buf, path, where, order)
            buf = []
            _include(path, header[8:].strip(), k, fileconfig, where, order, files, visited)
        else:
            buf.append((k, line))
    _read_buffer(fileconfig, buf, path, where, order)
    visited.discard(real)


def _include(path: str, spec: str, line: int, fileconfig, where, order, files, visited) -> None:
    """klippy/configfile.py ``_resolve_include``."""
    pattern = os.path.join(os.path.dirname(path), spec)
    names = glob.glob(pattern)
    if not names and not glob.has_magic(pattern):
        raise InputFileError(path, f"[include {spec}]: no such file {pattern} (Klipper stops with 'Include file "
                             "does not exist')", line=line)
    for name in sorted(names):
        _parse(read_text(name), name, fileconfig, where, order, files, visited)


def _strip_duplicates(data: str, fileconfig) -> str:
    """klippy/configfile.py ``_strip_duplicates``: each option of ``data`` that
    ``fileconfig`` sets is commented out with ``#`` (and its continuation lines)."""
    comment_r, value_r = re.compile("[#;].*$"), re.compile("[^A-Za-z0-9_].*$")
    lines = data.split("\n")
    section, dup = None, False
    for k, line in enumerate(lines):
        pruned = comment_r.sub("", line).rstrip()
        if not pruned:
            continue
        if pruned[0].isspace():
            if dup:
                lines[k] = "#" + lines[k]
            continue
        dup = False
        if pruned[0] == "[":
            section = pruned[1:-1].strip()
            continue
        if section is not None and fileconfig.has_option(section, value_r.sub("", pruned)):
            dup = True
            lines[k] = "#" + lines[k]
    return "\n".join(lines)


def read_config(path: str) -> KlipperConfig:
    """The options Klipper runs with (module docstring)."""
    path = os.fspath(path)
    data = read_text(path)
    regular, autosave, ignored, block_line0 = find_autosave(data)
    fileconfig = _parser()
    where: dict = {}
    order: list[str] = []
    files: list[str] = []
    _parse(regular, path, fileconfig, where, order, files, set())
    notes = []
    if ignored:
        notes.append(f"{path}: the SAVE_CONFIG (#*#) block is ignored, as Klipper ignores it: {ignored}")
    from_block: set = set()
    if autosave:
        # the block's own options (as the parser sees them), then which the main file overrides
        own = _parser()
        _parse(autosave, path, own, {}, [], [], set(), includes=False)
        stripped = _strip_duplicates(autosave, fileconfig)
        overridden = sorted((s, o) for s in own.sections() for o in own.options(s) if fileconfig.has_option(s, o))
        block_where: dict = {}
        _parse(stripped, path, fileconfig, block_where, order, files, set(), line0=block_line0, includes=False)
        from_block = set(block_where)
        where.update(block_where)
        if overridden:
            shown = ", ".join(f"[{s}] {o}" for s, o in overridden)
            notes.append(f"{path}: the main file's {shown} override{'s' if len(overridden) == 1 else ''} the "
                         "SAVE_CONFIG block's (Klipper comments the block's out); delete "
                         f"{'it' if len(overridden) == 1 else 'them'} above the block to run the saved values")
    options = {}
    for section in fileconfig.sections():
        for option in fileconfig.options(section):
            p, line = where.get((section, option), (path, None))
            options[(section, option)] = Option(fileconfig.get(section, option), p, line)
    return KlipperConfig(path=path, options=options, sections=[s for s in order if fileconfig.has_section(s)],
                         files=files, from_block=from_block, notes=notes)


# -- SAVE_CONFIG ---------------------------------------------------------------------------------


def autosave_lines(parser) -> list[str]:
    """The sections of ``parser`` (a ``RawConfigParser``) as Klipper writes them into its
    SAVE_CONFIG block: ``RawConfigParser.write``'s lines, each behind ``#*# ``
    (klippy/configfile.py ``cmd_SAVE_CONFIG``)."""
    sfile = io.StringIO()
    parser.write(sfile)
    return [("#*# " + line).strip() for line in sfile.getvalue().strip().split("\n")]


def save_config_text(path: str, values: dict[str, dict[str, str]]) -> str:
    """The text of ``path`` after Klipper's ``SAVE_CONFIG`` with ``values`` (section →
    option → text) set by a calibration (klippy/configfile.py ``cmd_SAVE_CONFIG``): the
    block keeps its other sections and options, the main file's copies of the saved options
    are commented out."""
    data = read_text(path)
    regular, autosave, ignored, _ = find_autosave(data)
    if ignored:
        # cmd_SAVE_CONFIG: "Existing config autosave is corrupted. Can't complete SAVE_CONFIG"
        raise InputFileError(path, f"Klipper's SAVE_CONFIG refuses this file: {ignored}; repair the block first")
    block = _parser()
    if autosave:
        # the block as Klipper keeps it: the options the main file overrides commented out
        main = _parser()
        _parse(regular, path, main, {}, [], [], set())
        _parse(_strip_duplicates(autosave, main), path, block, {}, [], [], set(), includes=False)
    for section, opts in values.items():
        if not block.has_section(section):
            block.add_section(section)
        for option, text in opts.items():
            block.set(section, option, text)
    lines = autosave_lines(block)
    lines.insert(0, "\n" + AUTOSAVE_HEADER.rstrip())
    lines.append("")
    new_regular = _strip_duplicates(regular, block)
    # _disallow_include_conflicts: an included file may not set what the block sets
    included = _parser()
    where: dict = {}
    files: list[str] = []
    _parse(new_regular, path, included, where, [], files, set())
    for section in block.sections():
        for option in block.options(section):
            if included.has_option(section, option):
                src, line = where.get((section, option), (path, None))
                raise PkmcalError(f"{src}{f':{line}' if line else ''}: [{section}] {option} is set in an included "
                                  "file; Klipper's SAVE_CONFIG refuses that ('conflicts with included value'): "
                                  "remove it there")
    return new_regular.rstrip() + "\n".join(lines)


__all__ = ["AUTOSAVE_HEADER", "KlipperConfig", "Option", "find_autosave", "read_config", "read_text",
           "save_config_text"]
