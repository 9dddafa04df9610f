"""Abilities are declared, not probed (issue 12; docs/architecture.md).

Outside ``mechanisms/`` and ``sensors/``, no code asks a mechanism or a sensor what it is:
no ``isinstance``/``hasattr``/``getattr(obj, "attr", default)``/``type(obj) is`` on one, no
``try … except TypeError`` around an optional keyword. The grep below finds such probes by
the names the code base gives mechanisms and sensors (``mech``, ``machine``, ``nominal``,
``sensor``, …). The sites that remain are listed in :data:`ALLOWED`, each with the step of
issue 12 that removes it; the list may only shrink: a listed site that no longer exists
fails the test too, so the entry is deleted with the code.
"""

from __future__ import annotations

import re
from pathlib import Path

import pkmcal

SRC = Path(pkmcal.__file__).parent

_SUBJECT = (r"(?:self\.)?(?:mech|mechanism|machine|nominal|nom|cal|calibrated|model|frames|reference|real|sensor|s|m|other|back|base|load_point|"
            r"setup\.sensor|result\.sensor|result\.mechanism|model\.mechanism|model\.sensor)")
PROBE = re.compile(
    rf"\b(?:isinstance|hasattr)\(\s*{_SUBJECT}\s*,"               # isinstance(mech, …), hasattr(sensor, …)
    rf"|\bgetattr\(\s*{_SUBJECT}\s*,\s*[^,()]+,"                  # getattr(mech, "attr", default)
    rf"|\btype\(\s*(?:{_SUBJECT}|cal)\s*\)\s+is\b"                # type(real) is type(nominal)
    r"|\bexcept\s+TypeError\b"                                    # optional keywords probed by calling
)

#: (file under src/pkmcal, text of the probe, what removes it). Registries = issue 12 item 2
#: (mechanism/sensor kinds with their file schema, generic loaders, CLI/report/export asking
#: the registry); pipeline = item 3 (one simulate/verify/perturb); workspace = item 1's
#: ``workspace_box()`` and ``check_limits(margin=)`` adopted by planning.
ALLOWED = {
}


def _probes() -> set[tuple[str, str]]:
    found = set()
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(SRC).as_posix()
        if rel.startswith(("mechanisms/", "sensors/")):
            continue
        for line in path.read_text(encoding="utf-8").splitlines():
            if PROBE.search(line):
                found.add((rel, line.strip()))
    return found


def test_no_new_probes_of_mechanism_or_sensor_types():
    allowed = {(f, text) for f, text, _ in ALLOWED}
    unlisted = sorted((f, line) for f, line in _probes() if not any(f == af and t in line for af, t in allowed))
    assert not unlisted, ("probes of mechanism/sensor types outside mechanisms/ and sensors/; declare an ability "
                          f"or a method instead (docs/architecture.md): {unlisted}")


def test_the_allow_list_only_shrinks():
    probes = _probes()
    stale = sorted((f, t) for f, t, _ in ALLOWED if not any(pf == f and t in line for pf, line in probes))
    assert not stale, f"these allowed probes are gone: delete them from ALLOWED: {stale}"


def test_the_grep_finds_a_probe():
    """The pattern has teeth: each kind of probe it must catch, and a data-type check it must not."""
    for line in ('if isinstance(sensor, IndicatorSensor):', 'hasattr(mech, "leg_lengths")',
                 'getattr(machine, "stroke", None)', 'if type(real) is not type(nominal):', 'except TypeError:'):
        assert PROBE.search(line), line
    for line in ('isinstance(value, TextFloat)', 'getattr(m, key)[i]', '"leg-lengths" in mech.abilities'):
        assert not PROBE.search(line), line
