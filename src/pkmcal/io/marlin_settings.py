"""Marlin's delta settings (``M665``/``M666``, as ``M503`` prints them or a G-code file sets
them), read as each Marlin version runs them, and written for one.

The letters of ``M665`` changed meaning between versions, and so did what homing does with
``M666``. Cited from Marlin's sources (MarlinFirmware/Marlin; 1.1.x: ``Marlin/Marlin_main.cpp``
``gcode_M665``, ``homeaxis``, ``set_axis_is_at_home`` and ``Marlin/configuration_store.cpp``
``Config_PrintSettings``/``MarlinSettings::report``; 2.x: ``Marlin/src/gcode/calibrate/M665.cpp``
``GcodeSuite::M665`` (and ``M665_report`` in 2.1), ``Marlin/src/module/motion.cpp``
``homeaxis``/``set_axis_is_at_home``, ``Marlin/src/module/configuration_store.cpp`` (2.0) /
``settings.cpp`` ``MarlinSettings::report``, ``Marlin/src/module/delta.cpp``
``recalc_delta_settings``):

============  ==========================  ================================================
version       M665 words (M503 order)     homing after the switch (``homeaxis``, DELTA)
============  ==========================  ================================================
``1.1.x``     ``L R S A B C I J K``       carriage moved down |adj| when adj < 0
``1.1.9``     ``L R H S B X Y Z``         moved down |adj| + 0.1 mm when adj <= 0
``2.0.x``     ``L R H S B X Y Z``         moved down |adj| + (MIN_STEPS_PER_SEGMENT + 1) steps
``2.1.x``     ``L R H S X Y Z A B C``     moved down |adj| only when |adj| > MIN_STEPS_PER_SEGMENT steps
============  ==========================  ================================================

* L the diagonal rod, R the delta radius, S segments per second (not geometry);
  ``1.1.x`` and ``2.1.x``: A B C the per-tower rod trims (rod_i = L + trim_i), ``1.1.x`` I J K
  and the others X Y Z the tower angle trims (tower i at 210°, 330°, 90° + trim_i,
  ``recalc_delta_settings``); ``1.1.9``/``2.0.x``: **B is the probing (calibration) radius**,
  not a rod trim, and the rod trims are the compile-time ``DELTA_DIAGONAL_ROD_TRIM_TOWER``,
  which M503 does not print (0 unless the build sets them: a named default, noted).
* H the nozzle height at home (``1.1.x`` has no H: the height is the compile-time
  ``DELTA_HEIGHT``/``MANUAL_Z_HOME_POS`` plus ``M206 Z``, which the user must give). 2.x with a
  bed probe (M503 prints ``M851``): the nozzle at home is at H − the M851 Z offset
  (``set_axis_is_at_home``: ``delta_height - probe.offset.z``).
* M666 X Y Z: endstop adjustments, ≤ 0 (2.x's M666 refuses positive ones). After the switch,
  homing moves carriage i down by d_i (the table) and calls that position the nozzle at home
  height H_home, so the nozzle height on the axis with carriage i at its switch — pkmcal's
  (and Klipper's) ``position_endstop`` — is E_i = H_home + d_i.
* The steps per mm (``M92 X Y Z``, towers A B C) are needed where d_i counts steps (2.0.x, and
  2.1.x with a non-zero adjustment); ``MIN_STEPS_PER_SEGMENT`` is Marlin's default 6
  (Configuration_adv.h) unless given.

What cannot be told from the text must be stated (``version``): a text with I J K is
``1.1.x``; one with A or C is ``2.1.x`` (Marlin 2.0.6–2.0.9 print these words too but home
with 2.0.x's extra steps, which is not modelled for them: a known gap); any other
text (B without A and C, or no trim words) reads differently in 1.1.9, 2.0.x and 2.1.x, so
the version is required. A setting a version prints but the text lacks is an error
(``missing="zero"`` takes 0 for absent trims and adjustments, named in a note).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from pkmcal.errors import InputFileError, PkmcalError

MARLIN_VERSIONS = ("1.1.x", "1.1.9", "2.0.x", "2.1.x")
#: Marlin's tower angles before the trims (Marlin/src/module/delta.cpp recalc_delta_settings).
TOWER_ANGLES_DEG = (210.0, 330.0, 90.0)
#: Configuration_adv.h's default.
MIN_STEPS_PER_SEGMENT = 6


@dataclass(frozen=True)
class _Dialect:
    words: str             # the M665 words M503 prints, in its order
    rod_trims: str         # the letters of the rod trims a, b, c ('' : compile-time)
    angle_trims: str
    has_height: bool
    probe_in_height: bool  # the nozzle at home is at H − M851 Z


DIALECTS = {
    "1.1.x": _Dialect("LRSABCIJK", "ABC", "IJK", False, False),
    "1.1.9": _Dialect("LRHSBXYZ", "", "XYZ", True, False),
    "2.0.x": _Dialect("LRHSBXYZ", "", "XYZ", True, True),
    "2.1.x": _Dialect("LRHSXYZABC", "ABC", "XYZ", True, True),
}

_WORD = re.compile(r"([A-Za-z])\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)")


@dataclass(frozen=True)
class MarlinImport:
    firmware: object      # DeltaFirmware
    version: str
    notes: tuple[str, ...]


def _lines(path: str) -> list[str]:
    from pkmcal.io.inputs import read_input_text   # regular files only, UTF-8 errors with their line

    return read_input_text(path, "Marlin settings file").splitlines()


def _codes(path: str) -> dict[str, tuple[dict[str, float], dict[str, int]]]:
    """Per G-code (665, 666, 92, 851): the words set (later lines override earlier ones, as
    Marlin runs them) and the line of each."""
    out: dict[str, tuple[dict[str, float], dict[str, int]]] = {c: ({}, {}) for c in ("665", "666", "92", "851")}
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
        for letter, number in words:
            v = float(number)
            if not np.isfinite(v):
                raise InputFileError(path, f"M{code.group(1)} {letter.upper()}: not a finite number", line=k)
            values[letter.upper()] = v
            where[letter.upper()] = k
    return out


def _version(path: str, letters: set[str], version: str | None) -> tuple[str, list[str]]:
    """The version whose M665 the text is (module docstring), or the stated one checked."""
    if version is not None:
        if version not in DIALECTS:
            raise PkmcalError(f"--marlin-version {version}: choose one of {', '.join(MARLIN_VERSIONS)}")
        extra = sorted(letters - set(DIALECTS[version].words))
        if extra:
            raise InputFileError(path, f"M665 {' '.join(extra)} is not a Marlin {version} word (its M665 takes "
                                 f"{' '.join(DIALECTS[version].words)}); is the version right?")
        return version, []
    if letters & set("IJK"):
        if letters & set("HXYZ"):
            raise InputFileError(path, "M665 mixes I J K (Marlin 1.1.x angle trims) with H or X Y Z (later Marlin); "
                                 "give one version's M503 output")
        return "1.1.x", ["the M665 words I J K are Marlin 1.1.x's (A B C rod trims, I J K angle trims)"]
    if letters & set("AC"):
        return "2.1.x", ["the M665 words A and C are Marlin 2.1.x's rod trims (B tower B's), read with 2.1.x's homing "
                         "(Marlin 2.0.6-2.0.9 print them too but home MIN_STEPS_PER_SEGMENT + 1 steps further, which "
                         "pkmcal does not model for them)"]
    hint = ("B is the calibration radius in 1.1.9 and 2.0.x and tower B's rod trim in 2.1.x" if "B" in letters else
            "1.1.9, 2.0.x and 2.1.x home differently (the height each tower's switch is at)")
    raise InputFileError(path, f"which Marlin printed this? {hint}: give --marlin-version "
                         f"{'|'.join(MARLIN_VERSIONS)} (M115 prints it)")


def read_marlin_settings(path: str, version: str | None = None, *, missing: str = "error",
                         height: float | None = None,
                         min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT) -> MarlinImport:
    """The delta Marlin ``version`` runs from ``path`` (module docstring); ``height`` the
    nozzle height at home for 1.1.x (which has no M665 H)."""
    from pkmcal.io.delta_firmware import DeltaFirmware

    path = str(path)
    if missing not in ("error", "zero"):
        raise PkmcalError(f"missing='{missing}': 'error' or 'zero'")
    codes = _codes(path)
    m665, m666, m92, m851 = (codes[c][0] for c in ("665", "666", "92", "851"))
    if not m665:
        raise InputFileError(path, "no M665 line; print the delta settings with M503")
    version, notes = _version(path, set(m665), version)
    d = DIALECTS[version]
    need = ["L", "R"] + (["H"] if d.has_height else [])
    for letter in need:
        if letter not in m665:
            raise InputFileError(path, f"no M665 {letter} value; Marlin {version}'s M503 prints it (L the diagonal rod, "
                                 "R the radius, H the height)")
    absent = [c for c in d.rod_trims + d.angle_trims if c not in m665]
    absent666 = [c for c in "XYZ" if c not in m666]
    if absent or absent666:
        what = [f"M665 {' '.join(absent)}"] if absent else []
        what += [f"M666 {' '.join(absent666)}"] if absent666 else []
        if missing == "error":
            raise InputFileError(path, f"no {' and '.join(what)}: Marlin {version}'s M503 prints them; give its whole "
                                 "output, or take them as 0 with --missing zero")
        notes.append(f"{' and '.join(what)} not in the file: taken as 0 (--missing zero)")
    if d.has_height:
        if height is not None:
            raise PkmcalError(f"--height is for Marlin 1.1.x (no M665 H); Marlin {version} prints M665 H")
        H = m665["H"]
    else:
        if height is None:
            raise InputFileError(path, "Marlin 1.1.x's M665 has no H: give the nozzle height at home with --height "
                                 "(Configuration.h MANUAL_Z_HOME_POS plus M206 Z)")
        H = float(height)
    if d.probe_in_height and "Z" in m851:
        H -= m851["Z"]
        notes.append(f"M851 Z {m851['Z']:g}: the nozzle at home is at H - Z = {H:g} mm (Marlin {version} "
                     "set_axis_is_at_home)")
    rods = tuple(m665["L"] + (m665.get(c, 0.0) if d.rod_trims else 0.0) for c in (d.rod_trims or "ABC"))
    if not d.rod_trims:
        notes.append(f"Marlin {version}'s rod trims are Configuration.h's DELTA_DIAGONAL_ROD_TRIM_TOWER, not printed "
                     "by M503: taken as its default 0 (if your build sets them, add them to the arms)")
    angles = tuple(a + m665.get(c, 0.0) for a, c in zip(TOWER_ANGLES_DEG, d.angle_trims))
    adj = np.array([m666.get(c, 0.0) for c in "XYZ"])
    if np.any(adj > 0):
        raise InputFileError(path, "M666 endstop adjustments must be ≤ 0 (Marlin ignores positive ones); got "
                             f"{', '.join(f'{c}{a:g}' for c, a in zip('XYZ', adj))}")
    drop = _homing_drop(path, version, adj, m92, min_steps_per_segment, notes)
    return MarlinImport(DeltaFirmware(radius=m665["R"], angles_deg=angles, arms=rods,
                                      endstops=tuple(float(H + v) for v in drop)), version, tuple(notes))


def _steps(path: str, m92: dict, what: str) -> np.ndarray:
    if not all(c in m92 for c in "XYZ"):
        raise InputFileError(path, f"{what} needs the towers' steps per mm: give M503's 'M92 X… Y… Z…' line too")
    steps = np.array([m92[c] for c in "XYZ"])
    if not np.all(steps > 0):
        raise InputFileError(path, "M92 X Y Z must be positive steps per mm")
    return steps


def _homing_drop(path, version, adj, m92, min_steps, notes) -> np.ndarray:
    """d_i: how far below its switch homing leaves carriage i (module docstring table)."""
    if version == "1.1.x":          # Marlin_main.cpp homeaxis: do_homing_move(axis, endstop_adj[axis]) if < 0
        return -adj
    if version == "1.1.9":          # Marlin_main.cpp homeaxis: endstop_adj - 0.1 when <= 0
        notes.append("Marlin 1.1.9 homing moves each carriage 0.1 mm below its M666 adjustment (homeaxis): the "
                     "switches are 0.1 mm higher than H - M666")
        return -adj + 0.1
    if version == "2.0.x":          # motion.cpp homeaxis: adj - (MIN_STEPS_PER_SEGMENT + 1) steps when <= 0
        step = 1.0 / _steps(path, m92, "Marlin 2.0.x's homing (MIN_STEPS_PER_SEGMENT + 1 steps below the adjustment)")
        notes.append(f"Marlin 2.0.x homing moves each carriage {min_steps + 1} steps below its M666 adjustment "
                     f"(homeaxis; MIN_STEPS_PER_SEGMENT {min_steps})")
        return -adj + (min_steps + 1) * step
    # 2.1.x motion.cpp homeaxis: the adjustment is moved only when more than MIN_STEPS_PER_SEGMENT steps
    if not np.any(adj != 0):
        return -adj
    if not all(c in m92 for c in "XYZ") and np.all((adj == 0) | (adj <= -HOME_MARGIN_21)):
        notes.append(f"no M92 line: every M666 adjustment is 0 or at least {HOME_MARGIN_21:g} mm, which Marlin 2.1.x "
                     "moves on towers of more than 12 steps/mm (more than MIN_STEPS_PER_SEGMENT steps)")
        return -adj
    step = 1.0 / _steps(path, m92, "Marlin 2.1.x's homing (adjustments of MIN_STEPS_PER_SEGMENT steps or fewer are "
                                   "skipped)")
    moved = np.abs(adj) > min_steps * step
    skipped = [f"{c}{a:g}" for c, a, m in zip("XYZ", adj, moved) if a != 0 and not m]
    if skipped:
        notes.append(f"M666 {' '.join(skipped)}: Marlin 2.1.x skips adjustments of {min_steps} steps or fewer "
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


#: How far below the lowest switch the exported H is for 2.1.x, so that every M666 is more
#: than MIN_STEPS_PER_SEGMENT steps (moved by homing) on towers of more than 12 steps/mm.
HOME_MARGIN_21 = 0.5


def _marlin_words(fw, version: str, steps_per_mm: tuple | None, min_steps_per_segment: int):
    """(M665 words, M666 adjustments (3,), the homing's extra drop (3,), what the version
    cannot hold) for ``fw`` in Marlin ``version``, unrounded (:func:`marlin_text`)."""
    if version not in DIALECTS:
        raise PkmcalError(f"--marlin-version {version}: choose one of {', '.join(MARLIN_VERSIONS)}")
    if version == "1.1.x":
        raise PkmcalError("Marlin 1.1.x sets the height in Configuration.h and M206, not M665: export for 1.1.9, "
                          "2.0.x or 2.1.x")
    d = DIALECTS[version]
    ends = np.array(fw.endstops, dtype=float)
    dropped = []
    L = float(np.mean(fw.arms))
    if not d.rod_trims and len(set(fw.arms)) > 1:
        dropped.append(f"arms {', '.join(f'{a:.6g}' for a in fw.arms)} mm: Marlin {version} has one rod length in "
                       f"M665 (per-tower trims only in Configuration.h DELTA_DIAGONAL_ROD_TRIM_TOWER); L = {L:.6g}")
    if version == "1.1.9":
        extra = np.full(3, 0.1)
    elif version == "2.0.x":
        if steps_per_mm is None:
            raise PkmcalError("Marlin 2.0.x homing adds MIN_STEPS_PER_SEGMENT + 1 steps below each adjustment: give "
                              "the towers' steps per mm (--steps-per-mm, M92's X Y Z)")
        extra = (min_steps_per_segment + 1) / np.broadcast_to(np.asarray(steps_per_mm, dtype=float), (3,))
    else:
        extra = np.zeros(3)
    # E_i = H + extra_i − adj_i with every adj ≤ 0 (2.1.x: < −MIN_STEPS_PER_SEGMENT steps)
    margin = HOME_MARGIN_21 if version == "2.1.x" else 0.0
    H = float(np.min(ends - extra)) - margin
    adj = np.minimum(H + extra - ends, 0.0)
    words = {"L": L, "R": fw.radius, "H": H}
    words.update({c: a - n for c, a, n in zip("XYZ", fw.angles_deg, TOWER_ANGLES_DEG)})
    if d.rod_trims:
        words.update({c: a - L for c, a in zip("ABC", fw.arms)})
    return words, adj, extra, dropped


def marlin_text(fw, version: str = "2.1.x", steps_per_mm: tuple | None = None,
                min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT) -> tuple[str, list[str]]:
    """(``M665``/``M666`` lines then ``M500``, what the version cannot hold) for ``fw``
    (module docstring), after a comment line saying how the numbers are rounded
    (:data:`MARLIN_ROUNDING`, :func:`_number`). The height and adjustments are chosen so
    that the version's homing puts each switch at the firmware's position_endstop: E_i =
    H + d_i."""
    words, adj, _, dropped = _marlin_words(fw, version, steps_per_mm, min_steps_per_segment)
    m665 = "M665 " + " ".join(f"{c}{_number(v)}" for c, v in words.items())
    m666 = "M666 " + " ".join(f"{c}{_number(v)}" for c, v in zip("XYZ", adj))
    head = f"; Marlin {version}: M665 {' '.join(DIALECTS[version].words)}"
    return "\n".join([head, m665, m666, "M500 ; store in EEPROM", f"; pkmcal: {MARLIN_ROUNDING}", ""]), dropped


def marlin_rounded(fw, version: str = "2.1.x", steps_per_mm: tuple | None = None,
                   min_steps_per_segment: int = MIN_STEPS_PER_SEGMENT):
    """The firmware numbers (a :class:`~pkmcal.io.delta_firmware.DeltaFirmware`) that the
    words :func:`marlin_text` writes stand for, each word as written (what an import of the
    export gives): radius R, tower angles 210/330/90° + trims, rods L (+ trims where the
    version has them, else L for every tower), switches E_i = H + d_i − adj_i."""
    from dataclasses import replace

    words, adj, extra, _ = _marlin_words(fw, version, steps_per_mm, min_steps_per_segment)
    w = {c: float(_number(v)) for c, v in words.items()}
    a = np.array([float(_number(v)) for v in adj])
    trims = DIALECTS[version].rod_trims
    arms = tuple(w["L"] + w[c] for c in trims) if trims else (w["L"],) * 3
    return replace(fw, radius=w["R"], angles_deg=tuple(n + w[c] for c, n in zip("XYZ", TOWER_ANGLES_DEG)),
                   arms=arms, endstops=tuple(float(e) for e in w["H"] + extra - a))


__all__ = ["DIALECTS", "MARLIN_ROUNDING", "MARLIN_VERSIONS", "MIN_STEPS_PER_SEGMENT", "MarlinImport", "marlin_rounded",
           "marlin_text", "read_marlin_settings"]
