"""Marlin's delta settings (``M665``/``M666``, as ``M503`` prints them or a G-code file sets
them), read as each Marlin release runs them, and written for one.

The letters of ``M665`` changed meaning between releases, and so did what homing does with
``M666``. Each rule is cited to Marlin's sources (MarlinFirmware/Marlin; 1.1.x:
``Marlin/Marlin_main.cpp`` ``gcode_M665``, ``gcode_M666``, ``homeaxis``,
``set_axis_is_at_home``, ``recalc_delta_settings`` and ``Marlin/configuration_store.cpp``
``MarlinSettings::report``; 2.x: ``Marlin/src/gcode/calibrate/M665.cpp`` ``GcodeSuite::M665``
(and ``M665_report`` from 2.0.9.2), ``Marlin/src/gcode/calibrate/M666.cpp``,
``Marlin/src/module/motion.cpp`` ``homeaxis``/``set_axis_is_at_home``,
``Marlin/src/module/configuration_store.cpp`` (``settings.cpp`` later)
``MarlinSettings::report``, ``Marlin/src/module/delta.cpp`` ``recalc_delta_settings``).

Each boundary is the first **release** whose source holds the rule: the upstream repository
(1.2 GB) is over the size pkmcal's tools can fetch, so the release points were read from a
fork that carries upstream's whole history (thisiskeithb/Marlin, 25 623 commits): a release
is the commit that sets ``Version.h``'s ``SHORT_BUILD_VERSION`` (1.1.0 03f94a7a18, 1.1.1
5996c3a907, 1.1.2 515f05093f, 1.1.5 9c00cff898, 1.1.6 8dc10fb4c2, 1.1.8 0640bd0282, 1.1.9
5cf6c44f47, 2.0.0 ac7ee4b94a, 2.0.5.4 5513e67512, 2.0.6 92076c6560, 2.0.9.4 369542db3b), each
rule's commit checked to be an ancestor of its first release and not of the one before (``git
merge-base --is-ancestor``), and each release's own files read. The 1.1.0 release candidates
(RC2–RC8) and the 2.1.x releases are not in that history: the candidates are bounded by
commits (1.1.0-RC2 91b5156b3e, RC5 6a245fe4f7, the RCBugFix of 2016-12-07 08cdaaf19b), 2.1.x
by bugfix-2.1.x, from which Marlin cuts it (docs: MarlinDocumentation ``_meta/releases.html``).

===============================  ==================  ==========================================================
rule                             releases            commit (first release), file / function
===============================  ==================  ==========================================================
M665 L R S A B C: rod trims      1.1.0-RC2 … RC8     4c8330c15c (RC2), Marlin_main.cpp gcode_M665, no H
M665 I J K: angle trims          none (RCBugFix      00b6b3da79 2017-02-27, removed by 13c8493878 2017-04-18
                                 only)               before 1.1.0: never in a release
M665 L R H S B X Y Z, **B the    1.1.0 … 1.1.9       13c8493878 (1.1.0), gcode_M665 /
calibration radius** (not                            configuration_store.cpp report
geometry), no rod trims
M665 Z turns towers A and B      1.1.0 … 1.1.5       13c8493878 (1.1.0): X, Y set A, B; Z subtracted from both;
(tower C held at 90°)                                recalc_delta_settings puts C at (0, R); M503 prints Z0.00
M665 Z: tower C's angle trim     1.1.6 …             74d430cb97 (1.1.6) "matrix names update", gcode_M665
M666 positive: normalised into   RC … 1.1.5          gcode_M666 (max subtracted from all and from H)
H; 1.1.6 on: a positive ignored  1.1.6 …             74d430cb97 (1.1.6); 2.x M666.cpp the same
homing: carriage moved |adj|     RC … 1.1.1          Marlin_main.cpp homeaxis: do_homing_move(adj) if adj < 0
(adj < 0)
homing: |adj| + 0.1 mm           1.1.2 … 1.1.8       6ce2b1ff4a (1.1.2) "G33 evolutionary changes", homeaxis
(adj <= 0)
homing: |adj| + (MIN_STEPS_PER_  1.1.9, 2.0.0 …      6e30d1bef1 (1.1.9) #10385; 12785583d0 (2.0.0) #10386,
SEGMENT + 1) steps (adj <= 0)    2.0.5.x             motion.cpp homeaxis
M665 L R H S X Y Z: no B         2.0.0 … 2.0.5.x     b904ba0f29 (2.0.0) #15887, M665.cpp GcodeSuite::M665
(M665 ignores it)
M665 L R H S X Y Z A B C: rod    2.0.6 … 2.1.x       29753baeee (2.0.6) #18423 "Adjustable
trims A B C (B: tower B's rod)                       delta_diagonal_rod_trim", M665.cpp, report
homing: |adj| only when more     2.0.6 … 2.1.x       ccfd5c1010 (2.0.6) #17299 "Trinamic steppers Homing
than MIN_STEPS_PER_SEGMENT steps                     Phase", motion.cpp homeaxis (adjDistance, minDistance)
nozzle at home = H − M851 Z      2.0.0 … 2.1.x       motion.cpp set_axis_is_at_home (delta_height −
(with a bed probe)                                   probe offset z); 1.1.x: H (its probe term is for
                                                     Z_HOME_DIR < 0 only)
===============================  ==================  ==========================================================

So the dialects (``DIALECTS``), by the releases that share every rule:

================  =========================  =============================================
dialect           M665 words (M503 order)    homing after the switch (``homeaxis``, DELTA)
================  =========================  =============================================
``1.1.0-RC``      ``L R S A B C`` [I J K]    carriage moved down |adj| when adj < 0
``1.1.0-1.1.1``   ``L R H S B X Y Z`` (Z     moved down |adj| when adj < 0
                  turns A and B)
``1.1.2-1.1.5``   the same                   moved down |adj| + 0.1 mm when adj <= 0
``1.1.6-1.1.8``   ``L R H S B X Y Z``        moved down |adj| + 0.1 mm when adj <= 0
``1.1.9``         ``L R H S B X Y Z``        |adj| + (MIN_STEPS_PER_SEGMENT + 1) steps
``2.0.0-2.0.5``   ``L R H S X Y Z``          |adj| + (MIN_STEPS_PER_SEGMENT + 1) steps
``2.0.6-2.1.x``   ``L R H S X Y Z A B C``    |adj| only when |adj| > MIN_STEPS_PER_SEGMENT steps
================  =========================  =============================================

Marlin 2.0.6 to 2.0.9.x print 2.1.x's words *and* home as 2.1.x does (the homing changed in
the same release as the words): one dialect. 1.1.9's homing is 2.0.0–2.0.5's, not 0.1 mm.

* L the diagonal rod, R the delta radius, S segments per second (not geometry); A B C the
  per-tower rod trims (rod_i = L + trim_i) where the dialect has them, else the compile-time
  ``DELTA_DIAGONAL_ROD_TRIM_TOWER``, which M503 does not print (0 unless the build sets them:
  a named default, noted); X Y Z (RC: I J K) the tower angle trims (tower i at 210°, 330°,
  90° + trim_i, ``recalc_delta_settings``). The compile-time ``DELTA_RADIUS_TRIM_TOWER`` is
  taken as its default 0 in every release.
* H the nozzle height at home (1.1.0–1.1.6 print ``DELTA_HEIGHT + home_offset[Z]``, which is
  the nozzle height with the example configurations' ``MANUAL_Z_HOME_POS DELTA_HEIGHT``;
  1.1.7 on keep ``delta_height``). The release candidates print no H: the height is the
  compile-time ``MANUAL_Z_HOME_POS`` plus ``M206 Z``, which the user gives (``height``); the
  RCBugFix builds of April 2017 print one. 2.x with a bed probe (M503 prints ``M851``): the
  nozzle at home is at H − the M851 Z offset.
* M666 X Y Z: endstop adjustments. After the switch, homing moves carriage i down by d_i (the
  table) and calls that position the nozzle at home height H_home, so the nozzle height on
  the axis with carriage i at its switch — pkmcal's (and Klipper's) ``position_endstop`` —
  is E_i = H_home + d_i. A positive adjustment is refused: 1.1.6 on ignore it (keeping the
  previous value), and up to 1.1.5 M666 moves the largest into H, which M503 prints already
  moved (give M503's output).
* The steps per mm (``M92 X Y Z``, towers A B C) are needed where d_i counts steps (1.1.9 to
  2.0.5.x, and 2.0.6 on with a non-zero adjustment); ``MIN_STEPS_PER_SEGMENT`` is Marlin's
  default 6 (Configuration_adv.h of 1.1.9 and 2.0.9) unless given.
* Not established: bugfix-2.1.x from 2023-10-06 (f7a3172c20, #26297) to its revert on
  2024-05-16 (bdc14ddbd7, #27088) left the M851 Z offset out of the home height unless
  ``USE_PROBE_FOR_Z_HOMING``; whether a 2.1.2.x maintenance release took it is not known here
  (the release notes read do not list it). A printer on such a build reads as H, not H − Z.

The version a user states (``version``) is a release as ``M115`` prints it (``1.1.8``,
``2.0.9.3``, ``2.1.2``), ``1.1.0-RC8``/``1.1.0-RCBugFix``, ``bugfix-2.1.x`` (``bugfix-2.0.x``
only with A B C in the text: its rules changed three times), a dialect's name, or one of the
earlier values ``1.1.x``, ``1.1.9``, ``2.0.x``, ``2.1.x`` (:func:`marlin_dialect`). What
cannot be told from the text must be stated: a text with I J K, or A or C without H, is a
1.1.0 release candidate's; one with A or C and H is 2.0.6–2.1.x's; any other text (B without
A and C, or no trim words) reads differently in 1.1.0–1.1.1, 1.1.2–1.1.8 and 1.1.9–2.0.5.x,
so the release is required. A setting a dialect prints but the text lacks is an error
(``missing="zero"`` takes 0 for absent trims and adjustments, named in a note).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError

#: Marlin's tower angles before the trims (Marlin/src/module/delta.cpp recalc_delta_settings).
TOWER_ANGLES_DEG = (210.0, 330.0, 90.0)
#: Configuration_adv.h's default.
MIN_STEPS_PER_SEGMENT = 6


@dataclass(frozen=True)
class _Dialect:
    releases: str          # the releases that run it, as said in messages
    words: str             # the M665 words M503 prints, in its order
    rod_trims: str         # the letters of the rod trims a, b, c ('' : compile-time)
    angle_trims: str
    has_height: bool       # M665 H (the release candidates: the user's height, or an RCBugFix H)
    probe_in_height: bool  # the nozzle at home is at H − M851 Z
    homing: str            # 'adj', 'adj+0.1', 'adj+steps', 'skip-small' (module docstring)
    z_turns: bool = False  # M665 Z subtracted from the A and B trims, tower C at 90°
    optional: str = ""     # words some of its builds print and others do not
    ignored: str = ""      # words its M665 does not parse (not geometry)


DIALECTS = {
    "1.1.0-RC": _Dialect("1.1.0-RC2...RC8 and RCBugFix", "LRSABCIJK", "ABC", "IJK", False, False, "adj",
                         optional="HIJK"),
    "1.1.0-1.1.1": _Dialect("1.1.0-1.1.1", "LRHSBXYZ", "", "XYZ", True, False, "adj", z_turns=True),
    "1.1.2-1.1.5": _Dialect("1.1.2-1.1.5", "LRHSBXYZ", "", "XYZ", True, False, "adj+0.1", z_turns=True),
    "1.1.6-1.1.8": _Dialect("1.1.6-1.1.8", "LRHSBXYZ", "", "XYZ", True, False, "adj+0.1"),
    "1.1.9": _Dialect("1.1.9", "LRHSBXYZ", "", "XYZ", True, False, "adj+steps"),
    "2.0.0-2.0.5": _Dialect("2.0.0-2.0.5.x", "LRHSXYZ", "", "XYZ", True, True, "adj+steps", ignored="B"),
    "2.0.6-2.1.x": _Dialect("2.0.6-2.1.x", "LRHSXYZABC", "ABC", "XYZ", True, True, "skip-small"),
}
#: The values :func:`marlin_dialect` takes besides a release number (``2.0.9.3``).
MARLIN_VERSIONS = ("1.1.0-RC", "1.1.x", "1.1.9", "2.0.x", "2.1.x", *DIALECTS)
_VERSION_HELP = ("a release as M115 prints it (e.g. 1.1.8, 2.0.5.3, 2.0.9.3, 2.1.2), 1.1.0-RC8, 1.1.x, 2.0.x or "
                 "2.1.x")
#: (first release, dialect), in order: a release runs the last dialect whose first release it
#: is not below (module docstring table).
_BOUNDS = (((1, 1, 0, 0), "1.1.0-1.1.1"), ((1, 1, 2, 0), "1.1.2-1.1.5"), ((1, 1, 6, 0), "1.1.6-1.1.8"),
           ((1, 1, 9, 0), "1.1.9"), ((2, 0, 0, 0), "2.0.0-2.0.5"), ((2, 0, 6, 0), "2.0.6-2.1.x"))
_LAST_KNOWN = (2, 1, 99, 99)      # the 2.1.x series; a later one is not established here

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


def _release(version: str) -> tuple[int, ...] | None:
    m = re.fullmatch(r"(\d+)\.(\d+)(?:\.(\d+))?(?:\.(\d+))?", version.strip())
    return None if m is None else tuple(int(g or 0) for g in m.groups())


def marlin_dialect(version: str, letters: set[str] | None = None) -> tuple[str, list[str]]:
    """(the dialect of :data:`DIALECTS` Marlin ``version`` runs, notes): a release number, a
    release candidate, a dialect's name, or the families ``1.1.x``/``2.0.x``/``2.1.x``;
    ``letters`` (the M665 words of the text, for an import) settle the families where the
    text tells. A family the text cannot settle is an error naming the releases."""
    v = str(version).strip()
    if v in DIALECTS:
        return v, []
    if re.fullmatch(r"1\.1\.0-?RC\w*", v, flags=re.IGNORECASE):
        return "1.1.0-RC", []
    if v in ("2.1.x", "bugfix-2.1.x"):
        # bugfix-2.1.x began after 2.0.9.4 (d08223429b, 2022-06-03) with 2.0.6's rules
        return "2.0.6-2.1.x", [] if v == "2.1.x" else [
            "bugfix-2.1.x read as 2.0.6-2.1.x (from 2023-10-06 to 2024-05-16 its home height left out the M851 Z "
            "offset unless USE_PROBE_FOR_Z_HOMING: #26297, reverted by #27088)"]
    letters = set() if letters is None else letters
    if v.lower().startswith("bugfix"):
        if v == "bugfix-2.0.x" and letters & set("AC"):
            return "2.0.6-2.1.x", ["bugfix-2.0.x with M665 A B C (from 2020-06-27, #18423): read as 2.0.6-2.1.x"]
        raise PkmcalError(f"--marlin-version {v}: a bugfix build's rules changed over time (bugfix-2.0.x: B until "
                          "2019-11-21, 7 extra homing steps until 2020-04-20, A B C from 2020-06-27): give the release "
                          "it was taken after, as M115 of that release prints it (e.g. 2.0.5.3)")
    if v == "1.1.x":
        if letters & set("IJK") or (letters & set("AC") and "H" not in letters):
            return "1.1.0-RC", ["M665 A B C without H (or with I J K): the words of the 1.1.0 release candidates"]
        raise PkmcalError("--marlin-version 1.1.x: Marlin 1.1.0-1.1.1, 1.1.2-1.1.8 and 1.1.9 home differently and "
                          "1.1.0-1.1.5 turn towers A and B with M665 Z: give the release as M115 prints it "
                          "(1.1.0 ... 1.1.9; 1.1.0-RC8 for a release candidate)")
    if v == "2.0.x":
        if letters & set("AC"):
            return "2.0.6-2.1.x", ["M665 A B C rod trims: Marlin 2.0.6 or later (2.0.6-2.0.9.x read and home as "
                                   "2.1.x)"]
        if letters:
            return "2.0.0-2.0.5", ["--marlin-version 2.0.x read as 2.0.0-2.0.5.x (M665 without A B C; 2.0.6 and "
                                   "later print A B C and home differently: if yours is one, give its number)"]
        raise PkmcalError("--marlin-version 2.0.x: Marlin 2.0.0-2.0.5.x and 2.0.6-2.0.9.x home differently (2.0.6 "
                          "moves an adjustment only when it is more than MIN_STEPS_PER_SEGMENT steps, without the "
                          "extra steps before it): give the release as M115 prints it, e.g. 2.0.5.3 or 2.0.9.3")
    r = _release(v)
    if r is not None:
        r = (r + (0, 0, 0, 0))[:4]
        if (1, 1, 0, 0) <= r <= _LAST_KNOWN:
            return [d for first, d in _BOUNDS if r >= first][-1], []
        raise PkmcalError(f"--marlin-version {v}: pkmcal knows Marlin 1.1.0 to 2.1.x (the rules of each are in "
                          "pkmcal/io/marlin_settings.py); give one of those")
    raise PkmcalError(f"--marlin-version {v}: give {_VERSION_HELP}")


@dataclass(frozen=True)
class MarlinImport:
    firmware: object      # DeltaFirmware
    version: str          # the dialect read (DIALECTS)
    notes: tuple[str, ...]


def _lines(path: str) -> list[str]:
    from pkmcal.io.inputs import read_input_text   # regular files only, UTF-8 errors with their line

    return read_input_text(path, "Marlin settings file").splitlines()


def _codes(path: str) -> tuple[dict[str, tuple[dict[str, float], dict[str, int]]], list[dict[str, float]]]:
    """Per G-code (665, 666, 92, 851): the words set (later lines override earlier ones, as
    Marlin runs them) and the line of each; and each M665 line's words in order (for the
    dialects whose M665 Z acts on what came before)."""
    out: dict[str, tuple[dict[str, float], dict[str, int]]] = {c: ({}, {}) for c in ("665", "666", "92", "851")}
    m665_lines: list[dict[str, float]] = []
    for k, raw in enumerate(_lines(path), start=1):
        line = raw.split(";", 1)[0].strip()
        line = re.sub(r"^(echo:|//)\s*", "", line).strip()
        code = re.match(r"^M(665|666|92|851)(?![0-9])(.*)$", line, flags=re.IGNORECASE)
        if not code:
            continue
        rest = code.group(2)
        words = _WORD.findall(rest)
        if _WORD.sub("", rest).strip():
            raise InputFileError(path, f"cannot read '{raw.strip()}' (expected letter-number words such as "
                                 "L215.0 R105.0)", line=k)
        values, where = out[code.group(1)]
        this = {}
        for letter, number in words:
            v = float(number)
            if not np.isfinite(v):
                raise InputFileError(path, f"M{code.group(1)} {letter.upper()}: not a finite number", line=k)
            values[letter.upper()] = v
            where[letter.upper()] = k
            this[letter.upper()] = v
        if code.group(1) == "665":
            m665_lines.append(this)
    return out, m665_lines


def _version(path: str, letters: set[str], version: str | None) -> tuple[str, list[str]]:
    """The dialect whose M665 the text is (module docstring), or the stated version's, checked
    against the text's words."""
    if version is not None:
        key, notes = marlin_dialect(version, letters)
        d = DIALECTS[key]
        extra = sorted(letters - set(d.words + d.optional + d.ignored))
        if extra:
            raise InputFileError(path, f"M665 {' '.join(extra)} is not a word of Marlin {d.releases} (its M665 takes "
                                 f"{' '.join(d.words)}); is the version right?")
        return key, notes
    if letters & set("IJK") or (letters & set("AC") and "H" not in letters):
        if letters & set("XYZ"):
            raise InputFileError(path, "M665 mixes I J K or A B C without H (Marlin 1.1.0 release candidates) with "
                                 "X Y Z (1.1.0 and later); give one version's M503 output")
        return "1.1.0-RC", ["M665 A B C without H (or with I J K): read as the Marlin 1.1.0 release candidates' "
                            "(A B C rod trims, I J K angle trims)"]
    if letters & set("AC"):
        return "2.0.6-2.1.x", ["the M665 words A and C are the rod trims of Marlin 2.0.6 to 2.1.x (B tower B's), "
                               "which all home alike"]
    hint = ("B is the calibration radius in 1.1.0-1.1.9 (not geometry) and tower B's rod trim in 2.0.6 and later"
            if "B" in letters else "Marlin 1.1.0-1.1.1, 1.1.2-1.1.8 and 1.1.9-2.0.5.x home differently")
    raise InputFileError(path, f"which Marlin printed this? {hint}: give --marlin-version as M115 prints it "
                         "(e.g. 1.1.8, 1.1.9, 2.0.5.3)")


def _angle_trims(d: _Dialect, m665: dict, m665_lines: list[dict]) -> tuple[float, float, float]:
    """The tower angle trims the dialect runs: the last value of each word, or for the
    dialects whose M665 Z turns towers A and B (1.1.0-1.1.5, Marlin_main.cpp gcode_M665:
    X, Y set the A, B trims, then Z is subtracted from both; recalc_delta_settings puts tower
    C at 90°) the lines run in order."""
    if not d.z_turns:
        return tuple(m665.get(c, 0.0) for c in d.angle_trims)
    a = b = 0.0
    for words in m665_lines:
        a, b = words.get("X", a), words.get("Y", b)
        if "Z" in words:
            a, b = a - words["Z"], b - words["Z"]
    return a, b, 0.0


def read_marlin_settings(path: str, version: str | None = None, *, missing: str = "error",
                         height: float | None = None,
                         min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT) -> MarlinImport:
    """The delta Marlin ``version`` runs from ``path`` (module docstring); ``height`` the
    nozzle height at home for the 1.1.0 release candidates (whose M665 has no H)."""
    from pkmcal.io.delta_firmware import DeltaFirmware

    path = str(path)
    if missing not in ("error", "zero"):
        raise PkmcalError(f"missing='{missing}': 'error' or 'zero'")
    codes, m665_lines = _codes(path)
    m665, m666, m92, m851 = (codes[c][0] for c in ("665", "666", "92", "851"))
    if not m665:
        raise InputFileError(path, "no M665 line; print the delta settings with M503")
    version, notes = _version(path, set(m665), version)
    d = DIALECTS[version]
    need = ["L", "R"] + (["H"] if d.has_height else [])
    for letter in need:
        if letter not in m665:
            raise InputFileError(path, f"no M665 {letter} value; Marlin {d.releases}'s M503 prints it (L the diagonal "
                                 "rod, R the radius, H the height)")
    absent = [c for c in d.rod_trims + d.angle_trims if c not in m665 and c not in d.optional]
    absent666 = [c for c in "XYZ" if c not in m666]
    if absent or absent666:
        what = [f"M665 {' '.join(absent)}"] if absent else []
        what += [f"M666 {' '.join(absent666)}"] if absent666 else []
        if missing == "error":
            raise InputFileError(path, f"no {' and '.join(what)}: Marlin {d.releases}'s M503 prints them; give its "
                                 "whole output, or take them as 0 with --missing zero")
        notes.append(f"{' and '.join(what)} not in the file: taken as 0 (--missing zero)")
    if version == "1.1.0-RC" and not set(d.angle_trims) & set(m665):
        notes.append("no M665 I J K: the 1.1.0 release candidates have no angle trims (towers at 210, 330, 90 deg)")
    if d.ignored and set(d.ignored) & set(m665):
        notes.append(f"M665 {' '.join(sorted(set(d.ignored) & set(m665)))}: not read by Marlin {d.releases}'s M665 "
                     "(the calibration radius of earlier builds), not geometry")
    if "H" in m665 and (d.has_height or "H" in d.optional):
        if height is not None:
            raise PkmcalError(f"--height is for the Marlin 1.1.0 release candidates' M665 without H; {path} has "
                              "M665 H")
        H = m665["H"]
    else:
        if height is None:
            raise InputFileError(path, "the M665 of the Marlin 1.1.0 release candidates has no H: give the nozzle "
                                 "height at home with --height (Configuration.h MANUAL_Z_HOME_POS plus M206 Z)")
        H = float(height)
    if d.probe_in_height and "Z" in m851:
        H -= m851["Z"]
        notes.append(f"M851 Z {m851['Z']:g}: the nozzle at home is at H - Z = {H:g} mm (Marlin {d.releases} "
                     "set_axis_is_at_home)")
    rods = tuple(m665["L"] + (m665.get(c, 0.0) if d.rod_trims else 0.0) for c in (d.rod_trims or "ABC"))
    if not d.rod_trims:
        notes.append(f"Marlin {d.releases}'s rod trims are Configuration.h's DELTA_DIAGONAL_ROD_TRIM_TOWER, not "
                     "printed by M503: taken as its default 0 (if your build sets them, add them to the arms)")
    trims = _angle_trims(d, m665, m665_lines)
    if d.z_turns and any(w.get("Z", 0.0) != 0.0 for w in m665_lines):
        notes.append(f"M665 Z turns towers A and B in Marlin {d.releases} (subtracted from their trims; tower C "
                     "stays at 90 deg)")
    angles = tuple(a + t for a, t in zip(TOWER_ANGLES_DEG, trims))
    adj = np.array([m666.get(c, 0.0) for c in "XYZ"])
    if np.any(adj > 0):
        why = ("it moves the largest into H, and M503 prints them moved: give M503's output" if d.z_turns or
               version == "1.1.0-RC" else "it ignores a positive one")
        raise InputFileError(path, f"M666 endstop adjustments must be ≤ 0 (Marlin {d.releases}: {why}); got "
                             f"{', '.join(f'{c}{a:g}' for c, a in zip('XYZ', adj))}")
    drop = _homing_drop(path, d, adj, m92, min_steps_per_segment, notes)
    return MarlinImport(DeltaFirmware(radius=m665["R"], angles_deg=angles, arms=rods,
                                      endstops=tuple(float(H + v) for v in drop)), version, tuple(notes))


def _steps(path: str, m92: dict, what: str) -> np.ndarray:
    if not all(c in m92 for c in "XYZ"):
        raise InputFileError(path, f"{what} needs the towers' steps per mm: give M503's 'M92 X… Y… Z…' line too")
    steps = np.array([m92[c] for c in "XYZ"])
    if not np.all(steps > 0):
        raise InputFileError(path, "M92 X Y Z must be positive steps per mm")
    return steps


def _homing_drop(path, d: _Dialect, adj, m92, min_steps, notes) -> np.ndarray:
    """d_i: how far below its switch homing leaves carriage i (module docstring tables)."""
    if d.homing == "adj":          # Marlin_main.cpp homeaxis: do_homing_move(axis, endstop_adj[axis]) if < 0
        return -adj
    if d.homing == "adj+0.1":      # Marlin_main.cpp homeaxis (1.1.2-1.1.8): endstop_adj - 0.1 when <= 0
        notes.append(f"Marlin {d.releases} homing moves each carriage 0.1 mm below its M666 adjustment (homeaxis): "
                     "the switches are 0.1 mm higher than H - M666")
        return -adj + 0.1
    if d.homing == "adj+steps":    # homeaxis (1.1.9; 2.0.0-2.0.5 motion.cpp): adj - (MIN_STEPS_PER_SEGMENT + 1) steps
        step = 1.0 / _steps(path, m92, f"Marlin {d.releases}'s homing (MIN_STEPS_PER_SEGMENT + 1 steps below the "
                                       "adjustment)")
        notes.append(f"Marlin {d.releases} homing moves each carriage {min_steps + 1} steps below its M666 adjustment "
                     f"(homeaxis; MIN_STEPS_PER_SEGMENT {min_steps})")
        return -adj + (min_steps + 1) * step
    # 2.0.6 on, motion.cpp homeaxis: the adjustment is moved only when more than MIN_STEPS_PER_SEGMENT steps
    if not np.any(adj != 0):
        return -adj
    if not all(c in m92 for c in "XYZ") and np.all((adj == 0) | (adj <= -HOME_MARGIN_21)):
        notes.append(f"no M92 line: every M666 adjustment is 0 or at least {HOME_MARGIN_21:g} mm, which Marlin "
                     f"{d.releases} moves on towers of more than 12 steps/mm (more than MIN_STEPS_PER_SEGMENT steps)")
        return -adj
    step = 1.0 / _steps(path, m92, f"Marlin {d.releases}'s homing (adjustments of MIN_STEPS_PER_SEGMENT steps or "
                                   "fewer are skipped)")
    moved = np.abs(adj) > min_steps * step
    skipped = [f"{c}{a:g}" for c, a, m in zip("XYZ", adj, moved) if a != 0 and not m]
    if skipped:
        notes.append(f"M666 {' '.join(skipped)}: Marlin {d.releases} skips adjustments of {min_steps} steps or fewer "
                     "(homeaxis, MIN_STEPS_PER_SEGMENT): that tower runs as if its adjustment were 0")
    return np.where(moved, -adj, 0.0)


#: The comment line (after ``; ``) of a Marlin export, and the export's message.
MARLIN_ROUNDING = ("numbers as Marlin holds them: 32-bit floats (about 7 significant digits), "
                   "at most 6 decimals (M665.cpp GcodeSuite::M665, parser.value_float)")


def _number(v: float) -> str:
    """``v`` at Marlin's own resolution: Marlin parses every ``M665``/``M666`` word into a
    32-bit float (``Marlin/src/gcode/calibrate/M665.cpp`` ``GcodeSuite::M665``,
    ``parser.value_linear_units``/``value_float``, strtof), keeps its delta settings as
    ``float`` (``Marlin/src/module/delta.cpp``) and stores them so in EEPROM
    (``Marlin/src/module/settings.cpp``). The value is rounded to 6 decimals (1e-6 mm, 1e-6°,
    like Klipper's) and written as the shortest decimal that reads back to the same 32-bit
    float, so the text is exactly what Marlin holds (to about 7 significant digits: 3e-5 mm
    at 300 mm). ``M503`` prints these settings with fewer decimals (``M665_report`` echoes
    each float through ``Marlin/src/core/serial.cpp`` ``serial_echopair_PGM``, whose
    ``SERIAL_DECIMAL`` prints 2 decimals unless the build sets Configuration_adv.h
    ``SERIAL_FLOAT_PRECISION``), so a configuration read back from ``M503`` is coarser than
    the one written."""
    v = float(v)
    if not np.isfinite(v):
        raise PkmcalError(f"cannot export a non-finite value ({v}) to Marlin")
    text = np.format_float_positional(np.float32(round(v, 6)), unique=True, trim="-")
    return "0" if float(text) == 0.0 else text


#: How far below the lowest switch the exported H is for 2.0.6 on, so that every M666 is more
#: than MIN_STEPS_PER_SEGMENT steps (moved by homing) on towers of more than 12 steps/mm.
HOME_MARGIN_21 = 0.5


def _marlin_words(fw, version: str, steps_per_mm: tuple | None, min_steps_per_segment: int):
    """(dialect, M665 words, M666 adjustments (3,), the homing's extra drop (3,), what the
    version cannot hold) for ``fw`` in Marlin ``version``, unrounded (:func:`marlin_text`)."""
    key, _ = marlin_dialect(version)
    d = DIALECTS[key]
    if key == "1.1.0-RC":
        raise PkmcalError("the Marlin 1.1.0 release candidates set the height in Configuration.h and M206, not M665: "
                          "export for a release (1.1.0 or later)")
    ends = np.array(fw.endstops, dtype=float)
    dropped = []
    L = float(np.mean(fw.arms))
    if not d.rod_trims and len(set(fw.arms)) > 1:
        dropped.append(f"arms {', '.join(f'{a:.6g}' for a in fw.arms)} mm: Marlin {d.releases} has one rod length in "
                       f"M665 (per-tower trims only in Configuration.h DELTA_DIAGONAL_ROD_TRIM_TOWER); L = {L:.6g}")
    trims = np.array(fw.angles_deg, dtype=float) - TOWER_ANGLES_DEG
    if d.z_turns and trims[2] != 0.0:
        # Marlin_main.cpp gcode_M665 / recalc_delta_settings (1.1.0-1.1.5): tower C stays at 90°,
        # so the towers are written turned by -trim_c about the centre: the same machine in a frame
        # turned by trim_c (the print turns with it)
        dropped.append(f"tower C at {fw.angles_deg[2]:.6g} deg: Marlin {d.releases} holds tower C at 90 deg (M665 Z "
                       f"turns towers A and B instead); the towers are written turned by {-trims[2]:+.6g} deg about "
                       f"the centre, so prints turn by {trims[2]:+.6g} deg about it")
        trims = trims - trims[2]
    if d.homing == "adj+0.1":
        extra = np.full(3, 0.1)
    elif d.homing == "adj+steps":
        if steps_per_mm is None:
            raise PkmcalError(f"Marlin {d.releases} homing adds MIN_STEPS_PER_SEGMENT + 1 steps below each adjustment: "
                              "give the towers' steps per mm (--steps-per-mm, M92's X Y Z)")
        extra = (min_steps_per_segment + 1) / np.broadcast_to(np.asarray(steps_per_mm, dtype=float), (3,))
    else:
        extra = np.zeros(3)
    # E_i = H + extra_i − adj_i with every adj ≤ 0 (2.0.6 on: < −MIN_STEPS_PER_SEGMENT steps)
    margin = HOME_MARGIN_21 if d.homing == "skip-small" else 0.0
    H = float(np.min(ends - extra)) - margin
    adj = np.minimum(H + extra - ends, 0.0)
    words = {"L": L, "R": fw.radius, "H": H}
    words.update(dict(zip("XYZ", trims)))
    if d.rod_trims:
        words.update({c: a - L for c, a in zip("ABC", fw.arms)})
    return key, words, adj, extra, dropped


def marlin_text(fw, version: str = "2.1.x", steps_per_mm: tuple | None = None,
                min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT) -> tuple[str, list[str]]:
    """(``M665``/``M666`` lines then ``M500``, what the version cannot hold) for ``fw``
    (module docstring), after a comment line saying how the numbers are rounded
    (:data:`MARLIN_ROUNDING`, :func:`_number`). The height and adjustments are chosen so
    that the version's homing puts each switch at the firmware's position_endstop: E_i =
    H + d_i."""
    key, words, adj, _, dropped = _marlin_words(fw, version, steps_per_mm, min_steps_per_segment)
    m665 = "M665 " + " ".join(f"{c}{_number(v)}" for c, v in words.items())
    m666 = "M666 " + " ".join(f"{c}{_number(v)}" for c, v in zip("XYZ", adj))
    head = f"; Marlin {DIALECTS[key].releases}: M665 {' '.join(DIALECTS[key].words)}"
    return "\n".join([head, m665, m666, "M500 ; store in EEPROM", f"; pkmcal: {MARLIN_ROUNDING}", ""]), dropped


def _held(fw, version, steps_per_mm, min_steps_per_segment, rounded: bool):
    from dataclasses import replace

    key, words, adj, extra, _ = _marlin_words(fw, version, steps_per_mm, min_steps_per_segment)
    w = {c: float(_number(v)) if rounded else float(v) for c, v in words.items()}
    a = np.array([float(_number(v)) if rounded else float(v) for v in adj])
    trims = DIALECTS[key].rod_trims
    arms = tuple(w["L"] + w[c] for c in trims) if trims else (w["L"],) * 3
    return replace(fw, radius=w["R"], angles_deg=tuple(n + w[c] for c, n in zip("XYZ", TOWER_ANGLES_DEG)),
                   arms=arms, endstops=tuple(float(e) for e in w["H"] + extra - a))


def marlin_rounded(fw, version: str = "2.1.x", steps_per_mm: tuple | None = None,
                   min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT):
    """The firmware numbers (a :class:`~pkmcal.io.delta_firmware.DeltaFirmware`) that the
    words :func:`marlin_text` writes stand for, each word as written (what an import of the
    export gives): radius R, tower angles 210/330/90° + trims, rods L (+ trims where the
    version has them, else L for every tower), switches E_i = H + d_i − adj_i."""
    return _held(fw, version, steps_per_mm, min_steps_per_segment, rounded=True)


def marlin_held(fw, version: str = "2.1.x", steps_per_mm: tuple | None = None,
                min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT):
    """The same numbers before the rounding of the words: what the version holds of ``fw``
    (one rod where it has no rod trims, tower C at 90° where M665 Z turns A and B), against
    which :func:`marlin_rounded` shows the rounding alone."""
    return _held(fw, version, steps_per_mm, min_steps_per_segment, rounded=False)


__all__ = ["DIALECTS", "MARLIN_ROUNDING", "MARLIN_VERSIONS", "MIN_STEPS_PER_SEGMENT", "MarlinImport", "marlin_dialect",
           "marlin_held", "marlin_rounded", "marlin_text", "read_marlin_settings"]
