"""Abilities are declared, not probed (issue 12; docs/architecture.md); the command line is a
shell over the library, and files sit below the engine (issue 27; DEVELOPERS.md, "Layers").

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


# --- The command line is a shell over the library (issue 27 item 2; DEVELOPERS.md) -------------

#: What a module of ``cli/`` may import: its own option, type and printing helpers
#: (``pkmcal.cli``), the library's front doors (``pkmcal.api``, the workflow layer), the
#: user-error type, the units and number printing, progress bars, and the file edge (``pkmcal.io``:
#: reading inputs, writing outputs).
CLI_MAY_IMPORT = ("pkmcal.cli", "pkmcal.api", "pkmcal.workflow", "pkmcal.errors", "pkmcal.conventions",
                  "pkmcal.progress", "pkmcal.io")

#: (file under cli/, module it imports beyond :data:`CLI_MAY_IMPORT`, why). Each command's one
#: library entry is listed as such; the rest is domain logic still to move into the workflow
#: layer (identify, identifiability, simulate, verify and export hold none), and the list may only shrink.
CLI_ALLOWED = {
    ("main.py", "pkmcal.allocator", "process set-up (the memory allocator) before any command"),
    ("demo_cmd.py", "pkmcal.demo", "the demo's library entry"),
    ("reproduce_cmd.py", "pkmcal.reproduce", "the reproductions' library entry"),
    ("study_cmd.py", "pkmcal.study", "the studies' library entry"),
    ("check_cmd.py", "pkmcal.controllers", "the controllers' library entry"),
    ("check_cmd.py", "pkmcal.controllers.klipper", "the controllers' library entry"),
    ("correct_cmd.py", "pkmcal.compensation.apply", "compensate/correct's library entry"),
    ("correct_cmd.py", "pkmcal.compensation.files", "compensate/correct's library entry"),
    ("correct_cmd.py", "pkmcal.compensation.fit", "compensate/correct's library entry"),
    ("correct_cmd.py", "pkmcal.compensation.gcode", "compensate/correct's library entry"),
    ("history_cmd.py", "pkmcal.history.plot", "the history's library entry"),
    ("history_cmd.py", "pkmcal.history.stats", "the history's library entry"),
    ("history_cmd.py", "pkmcal.history.store", "the history's library entry"),
}


def _imports(path: Path) -> set[str]:
    """The pkmcal modules ``path`` imports, at its top or inside a function."""
    import ast

    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m == "pkmcal" or m.startswith("pkmcal.")}


def _cli_imports_beyond_the_rule() -> set[tuple[str, str]]:
    out = set()
    for path in sorted((SRC / "cli").glob("*.py")):
        for module in _imports(path):
            if module != "pkmcal" and not any(module == p or module.startswith(p + ".") for p in CLI_MAY_IMPORT):
                out.add((path.name, module))
    return out


def test_cli_imports_only_the_front_doors():
    allowed = {(f, m) for f, m, _ in CLI_ALLOWED}
    extra = sorted(_cli_imports_beyond_the_rule() - allowed)
    assert not extra, ("cli/ parses options, calls pkmcal.api or pkmcal.workflow and prints (DEVELOPERS.md); "
                       f"move the domain logic these imports serve into the workflow layer: {extra}")


def test_the_cli_allow_list_only_shrinks():
    stale = sorted({(f, m) for f, m, _ in CLI_ALLOWED} - _cli_imports_beyond_the_rule())
    assert not stale, f"these cli imports are gone: delete them from CLI_ALLOWED: {stale}"


def test_identify_export_and_verify_hold_no_domain_logic():
    """The commands the workflow layer serves import nothing beyond the rule."""
    for name in ("identify_cmds.py", "export_cmd.py", "campaign_cmds.py"):
        assert not {m for f, m in _cli_imports_beyond_the_rule() if f == name}, name


def test_the_import_rule_has_teeth(tmp_path):
    """The parser sees imports at the top and inside functions, and nothing else."""
    src = tmp_path / "x.py"
    src.write_text("import pkmcal.identification.engine\ndef f():\n    from pkmcal.planning import plan\n"
                   "from pkmcal.io.tables import read_poses\nx = 'from pkmcal.sensors import y'\n")
    assert _imports(src) == {"pkmcal.identification.engine", "pkmcal.planning", "pkmcal.io.tables"}


def test_io_does_not_import_the_engine():
    """Files (io/) sit below identification/: nothing in io/ imports it (issue 27)."""
    offenders = sorted((p.name, m) for p in sorted((SRC / "io").glob("*.py")) for m in _imports(p)
                       if m.startswith("pkmcal.identification"))
    assert not offenders, offenders
