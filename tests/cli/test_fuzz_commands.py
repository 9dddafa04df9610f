"""Fuzzing every command, and one regression test per finding of issue 10 item 7.

The fuzz: each example takes one valid command line of one command (machine, setup,
measurement and pose files made once per module, copied fresh per example, the command run
in that folder) and breaks one thing:

* :func:`test_fuzz_every_command` — an input file: a YAML number (YAML 1.1 octal and
  base-60 forms, ``.nan``, ``1e308``, ``true``, quoted numbers), a name or description with
  a newline, degenerate joints or links, the YAML structure; a CSV cell, row, header or unit
  line, one to three poses left; or the argument list;
* :func:`test_fuzz_option_values` — a value: negative, zero, ``nan``, ``1e308``, empty, a
  path ending in ``/``, an input file, a folder, a 300-byte name, a newline, a broken
  ``symmetric:`` spec;
* :func:`test_fuzz_bad_output_locations` — an output (``-o``, ``--save-real``,
  ``--report``, ``--out``) in an impossible place.

The contract every outcome keeps (:func:`check_contract`): exit code 0 or 2; on 2 exactly one
stderr line starting ``pkmcal: error: `` (the last; only the note of a deprecated spelling
may precede it), no traceback, no output file and no temporary file left, and an error about
a machine names its file; never an input changed; never a RuntimeWarning; on 0 well-formed
outputs (:func:`check_outputs`). Property tests check that YAML numbers mean one thing to
every reader, that setup values are never coerced, that ``symmetric:`` machines and
measurements hold finite, plausible numbers. The tests after them pin each finding, with
the old behaviour in a comment.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import warnings
from pathlib import Path

import click
import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers import assert_user_error, cells, dump_yaml, fuzz_settings, mutate, structures
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pkmcal.cli.main import cli
from pkmcal.errors import PkmcalError
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io._yaml import parse_yaml
from pkmcal.io.atomic import atomic_writer, remove_stale_temporaries
from pkmcal.io.limits import MAX_MAGNITUDE
from pkmcal.io.machine_file import load_machine, machine_from_text, machine_to_text, save_machine
from pkmcal.io.measurements import save_measurements
from pkmcal.io.setup_file import builtin_setup, load_setup, save_setup
from pkmcal.io.tables import format_table, write_table
from pkmcal.mechanisms.library import planar_3dof_4act, stewart_prototype, stewart_prototype_real

HALF = np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])  # mm, deg: poses both prototypes reach
TEMP = re.compile(r"\..*\.pkmcal-[0-9a-f]{8}-[0-9]+-.*\.tmp")


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def _has_option(command: str, option: str) -> bool:
    cmd = cli.get_command(click.Context(cli), command)
    return any(option in p.opts for p in cmd.params)


# -- the valid inputs ----------------------------------------------------------------------------

def make_inputs(d: Path) -> None:
    """Valid files of every kind in folder ``d``."""
    nom, real = stewart_prototype(), stewart_prototype_real()
    save_machine(nom, d / "machine.yaml")
    save_machine(real, d / "real.yaml")
    save_machine(planar_3dof_4act(), d / "planar.yaml")
    cal = real.with_params(real.params, name="calibrated", covariance=np.diag(np.r_[np.full(42, 1e-4), np.zeros(6)]))
    save_machine(cal, d / "cal.yaml")
    rng = np.random.default_rng(1)
    p = rng.uniform(-1, 1, (14, 6)) * HALF
    p[:, :3] += nom.home_pose[:3]
    write_table(d / "poses.csv", {k: p[:, i] for i, k in enumerate("xyzabc")})
    internal = np.c_[p[:, :3], np.deg2rad(p[:, 3:])]
    lam = nom.ik(internal)
    write_table(d / "legs.csv", {f"lambda{i + 1}": lam[:, i] for i in range(6)})
    for name, builtin in (("ind", "indicators-prototype"), ("fp", "full-pose-paper1")):
        setup = builtin_setup(builtin)
        save_setup(setup, d / f"{name}.yaml")
        sim = simulate_campaign(nom, real, setup, internal, np.random.default_rng(2))
        save_measurements(d / f"meas_{name}.csv", sim.measurements, nom, setup)
    (d / "planar_setup.yaml").write_text(
        "sensor: planar-tool\ntarget: {x: 0, y: 0}\nnoise: {reading: 0.01, actuator: 0.001}\n"
        "simulation: {stiffness: 5.0e4, load: [0, -30]}\n")
    pl = planar_3dof_4act()
    pp = pl.sample_poses(6, np.random.default_rng(3), shrink=0.5)
    write_table(d / "planar_poses.csv", {"x": pp[:, 0], "y": pp[:, 1], "phi": np.rad2deg(pp[:, 2])})


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("inputs")
    make_inputs(d)
    return d


def templates() -> dict[str, list[str]]:
    """One valid command line per case; ``{}`` is the folder of the inputs and outputs."""
    obs_poses = ["--poses", "{}/poses.csv"] if _has_option("observability", "--poses") else ["{}/poses.csv"]
    info_n = "--n-poses" if _has_option("info", "--n-poses") else "--poses"
    return {
        "ik": ["ik", "{}/machine.yaml", "--poses", "{}/poses.csv", "-o", "{}/out.csv"],
        "fk": ["fk", "{}/machine.yaml", "{}/legs.csv", "-o", "{}/out.csv", "--guess", "0,0,315,0,0,0"],
        "observability": ["observability", "{}/machine.yaml", *obs_poses, "--setup", "{}/ind.yaml", "--json"],
        "identifiability": ["identifiability", "{}/machine.yaml", "--setup", "{}/ind.yaml", "--poses",
                            "{}/poses.csv", "--json"],
        "simulate": ["simulate", "{}/machine.yaml", "--real", "{}/real.yaml", "--setup", "{}/ind.yaml", "--poses",
                     "{}/poses.csv", "-o", "{}/out.csv", "--seed", "3"],
        "simulate-random": ["simulate", "{}/machine.yaml", "--random-errors", "0.5", "--setup", "{}/fp.yaml",
                            "--poses", "{}/poses.csv", "-o", "{}/out.csv", "--save-real", "{}/out.yaml",
                            "--ignore-limit", "leg_collision"],
        "simulate-planar": ["simulate", "{}/planar.yaml", "--real", "{}/planar.yaml", "--setup",
                            "{}/planar_setup.yaml", "--poses", "{}/planar_poses.csv", "-o", "{}/out.csv"],
        "identify": ["identify", "{}/machine.yaml", "{}/meas_fp.csv", "--setup", "{}/fp.yaml", "-o", "{}/out.yaml",
                     "--fix", "auto", "--json"],
        "identify-indicators": ["identify", "{}/machine.yaml", "{}/meas_ind.csv", "--setup", "{}/ind.yaml", "-o",
                                "{}/out.yaml", "--fix", "b?.*,a?.*"],
        "verify": ["verify", "{}/cal.yaml", "--real", "{}/real.yaml", "--poses", "{}/poses.csv", "--nominal",
                   "{}/machine.yaml", "--json", "-o", "{}/out.txt"],
        "export-hal": ["export", "{}/cal.yaml", "--format", "linuxcnc", "-o", "{}/out.hal"],
        "export-json": ["export", "{}/cal.yaml", "--format", "json", "-o", "{}/out.json"],
        "plan": ["plan", "{}/machine.yaml", "--setup", "{}/ind.yaml", "--n-poses", "14", "--n-candidates", "200",
                 "--algorithm", "random", "-o", "{}/out.csv", "--seed", "1"],
        "info": ["info", "{}/machine.yaml", info_n, "5", "--seed", "1"],
        "info-symmetric": ["info", "symmetric:base_radius=150,platform_radius=80", info_n, "5"],
        "machines": ["machines"],
    }


INPUT_KINDS = {".yaml": "yaml", ".csv": "csv"}


# -- the contract --------------------------------------------------------------------------------

def snapshot(d: Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in d.iterdir() if p.is_file()}


def _strict_json(text: str) -> None:
    def refuse(name):
        raise AssertionError(f"{name} in JSON output")
    json.loads(text, parse_constant=refuse)


def invoke(args: list[str], cwd: Path):
    """Run the command in-process in folder ``cwd`` (a relative output path lands there),
    with every RuntimeWarning recorded (pytest would otherwise swallow what a user sees on
    stderr)."""
    with warnings.catch_warnings(record=True) as caught, contextlib.chdir(cwd):
        warnings.simplefilter("always", RuntimeWarning)
        res = CliRunner().invoke(cli, args)
    res.runtime_warnings = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    return res


OUTPUT_OPTIONS = ("-o", "--output", "--save-real", "--report", "--out")
CSV_HEADER = re.compile(r"[a-z_][a-z0-9_.]*")


def _machine_files(args: list[str]) -> dict[str, str]:
    """name → path of the machine files on the command line (their ``name:`` line)."""
    out = {}
    for a in args:
        if a.endswith(".yaml") and os.path.isfile(a):
            m = re.search(r"^name: (.+)$", Path(a).read_text(encoding="utf-8", errors="replace"), re.MULTILINE)
            if m and not m.group(1).startswith(("'", '"')):
                out[m.group(1)] = a
    return out


def check_outputs(args: list[str], res) -> None:
    """What a successful command wrote or printed is well formed: no output path ending in
    '/' was accepted; every CSV has one header of column names and rows of its width; every
    HAL file has exactly the 36 'setp' lines of genhexkins as its only non-comment lines; no
    nan/inf in the numbers 'info' and 'identify' print; JSON is valid (no NaN)."""
    outs = [(a, args[i + 1]) for i, a in enumerate(args[:-1]) if a in OUTPUT_OPTIONS]
    assert not any(o.endswith("/") for _, o in outs), f"{args}: an output path ending in '/' was accepted"
    for option, o in outs:
        path = Path(o)
        if not path.is_file():
            continue
        kind = ("yaml" if option == "--save-real" or args[0] == "identify"
                else "csv" if args[0] in ("ik", "fk", "simulate", "plan")
                else "hal" if "linuxcnc" in args else "json" if "json" in args or "--json" in args else "text")
        text = path.read_text(encoding="utf-8")
        assert text.count("\n") == len(text.splitlines()), f"{o}: a line break other than \\n"
        lines = [line for line in text.splitlines() if line and not line.startswith("#")]
        if kind == "yaml":
            load_machine(o)
        elif kind == "json":
            _strict_json(text)
        elif kind == "csv":
            header = lines[0].split(",")
            assert all(CSV_HEADER.fullmatch(h) for h in header), (o, lines[0])
            assert all(len(line.split(",")) == len(header) for line in lines[1:] if '"' not in line), o
        elif kind == "hal":
            assert len(lines) == 36 and all(re.fullmatch(r"setp genhexkins\.(base|platform)\.[0-5]\.[xyz] \S+", line)
                                            for line in lines), lines
            assert max(len(line.encode()) for line in text.splitlines()) < 1024
    if args[0] in ("info", "identify") and "--json" not in args:
        printed = res.stdout
        for a in args:  # a file called 'nan' is no nan
            printed = printed.replace(a, "FILE")
        assert not re.search(r"(?<![\w.])-?(nan|inf)\b", printed), (args, res.stdout[-500:])
    if "--json" in args and res.stdout.strip() and (args[0] == "identify" or not outs):
        _strict_json(res.stdout)


def check_contract(res, d: Path, before: dict[str, str], args: list[str]) -> None:
    """The contract of every command on every input (module docstring)."""
    assert res.exit_code in (0, 2), (args, res.output, repr(res.exception))
    assert res.exception is None or isinstance(res.exception, SystemExit), (args, repr(res.exception))
    assert "Traceback" not in res.output
    assert not getattr(res, "runtime_warnings", []), (args, res.runtime_warnings)
    for marker in ("RuntimeWarning", "encountered in", "Warning:", "pkmcal: warning: numerical"):
        assert marker not in res.stderr, (args, res.stderr)
    after = snapshot(d)
    for name, digest in before.items():
        assert after.get(name) == digest, f"input {name} was changed or removed by {args}"
    assert not [n for n in os.listdir(d) if TEMP.fullmatch(n)], "a temporary file was left behind"
    if res.exit_code == 2:
        err = res.stderr
        lines = err.splitlines()
        # one error line, the last; before it at most the notes of deprecated spellings and the input's
        # warnings that may explain the error (angles that look like radians, ...: never numerical ones)
        assert err.endswith("\n") and err.count("\n") == len(lines), (args, err)
        assert lines[-1].startswith("pkmcal: error: "), (args, err)
        assert all(line.startswith("pkmcal: warning: ") for line in lines[:-1]), (args, err)
        assert set(after) == set(before), f"{args} failed but wrote {set(after) - set(before)}"
        for name, path in _machine_files(args).items():  # an error about a machine names its file
            if f"machine '{name}'" in err:
                assert path in err, (args, err)
    else:
        check_outputs(args, res)


# -- what is broken ------------------------------------------------------------------------------

NUMBER = re.compile(r"(?<![\w.\-+])-?\d+(\.\d*)?(e[-+]?\d+)?(?![\w.])")
YAML_NUMBERS = st.sampled_from(["0305", "010", "-012", "5:05", "1_000", "0b11", ".nan", ".inf", "-.inf", "1e308",
                                "-1e308", "true", "'0.01'", "0o17", "0x1F", "1e3", "0", "-1", "~", "[]", "{}",
                                "'305'", "no"])
NAME_LINES = st.sampled_from([
    'name: "x\\nsetp genhexkins.base.0.x 999"', 'description: "a\\nsetp genhexkins.base.0.x 999"',
    'description: "tab\\there"', 'name: "esc\\e[2J"', 'description: "line\\u2028sep"',
    "description: " + "d" * 3000, 'name: "' + "n" * 300 + '"', "free: [zero1, zero1]", "free: [zero1, nope]"])
CSV_CELLS = st.one_of(cells, st.sampled_from(["1e308", "-1e308", "1e400", "nan", "0x1", " 1", "1_0", "", "abc"]))
TOKENS = st.sampled_from(["", "-1", "-5", "0", "nan", "inf", "-inf", "1e308", "abc", "1,2", "OUT/", "LONG", "NL",
                          "/nonexistent/dir/out.csv", "INPUT", "DIR", "0x10", "2.5", "99999999999",
                          "symmetric:base_radius=nan", "symmetric:base_radius=0,platform_radius=0",
                          "symmetric:offset=1e308", "symmetric:base_radius=inf"])
NUMERIC = re.compile(r"[-0-9.,e+]+|symmetric:.*")
NUMERIC_TOKENS = st.sampled_from(["-1", "-5", "0", "nan", "inf", "-inf", "1e308", "-1e308", "", "abc", "99999999999",
                                  "1,2", "0,0,nan,0,0,0", "symmetric:base_radius=nan", "symmetric:offset=-1",
                                  "symmetric:platform_radius=0", "symmetric:stroke=1e308"])
#: Impossible places for an output file, and for an output folder (which is created if needed).
BAD_FILES = ("", "OUT/", "NODIR", "UNDERFILE", "LONG", "INPUT", "DIR")
BAD_FOLDERS = ("", "UNDERFILE", "DIRFILE", "LONG")


@st.composite
def yaml_edit(draw, text: str) -> str:
    lines = text.splitlines()
    how = draw(st.sampled_from(["number", "number", "name", "degenerate", "structure"]))
    if how == "number":
        spots = [(i, m) for i, line in enumerate(lines) if not line.lstrip().startswith("#")
                 for m in NUMBER.finditer(line)]
        if spots:
            i, m = draw(st.sampled_from(spots))
            lines[i] = lines[i][:m.start()] + draw(YAML_NUMBERS) + lines[i][m.end():]
            return "\n".join(lines) + "\n"
    if how == "name":
        new = draw(NAME_LINES)
        key = new.split(":")[0]
        lines = [line for line in lines if not line.startswith(key + ":")]
        lines.insert(1, new)
        return "\n".join(lines) + "\n"
    if how == "degenerate":  # every platform joint at the origin; a planar link of length 0
        text = re.sub(r"platform: \[[^\]]*\]", "platform: [0.0, 0.0, 0.0]", text)
        return re.sub(r"^(  (L3|rho\d\d|l\d\d)): [0-9.]+$", r"\1: 0.0", text, count=1, flags=re.MULTILINE)
    data = yaml.safe_load(text)
    return dump_yaml(mutate(draw, copy.deepcopy(data), st.one_of(structures, YAML_NUMBERS), st.sampled_from(
        ["name", "description", "legs", "offset", "stroke", "noise", "free", "zero", "parameters", "L3", "x"])))


@st.composite
def csv_edit(draw, text: str) -> str:
    rows = [line.split(",") for line in text.splitlines()]
    data = [k for k, r in enumerate(rows) if not r[0].startswith("#")][1:]
    for _ in range(draw(st.integers(1, 3))):
        how = draw(st.sampled_from(["cell", "cell", "cell", "drop", "dup", "units", "header", "keep", "empty"]))
        if how == "cell" and data:
            r = draw(st.sampled_from(data))
            rows[r][draw(st.integers(0, len(rows[r]) - 1))] = draw(CSV_CELLS)
        elif how == "drop" and len(data) > 1:
            k = draw(st.sampled_from(data))
            rows[k] = ["#dropped"]
        elif how == "dup" and data:
            rows.append(list(rows[draw(st.sampled_from(data))]))
        elif how == "units":
            rows.insert(0, [draw(st.sampled_from(["# units: length=m", "# units: angle=rad", "# units: length=um",
                                                  "# units: length=furlong"]))])
        elif how == "header" and data:
            h = data[0] - 1
            rows[h][draw(st.integers(0, len(rows[h]) - 1))] = draw(st.sampled_from(["", "x", "lambda1", "d1", "note"]))
        elif how == "keep" and data:  # one to three poses: one-pose fits, no degrees of freedom
            keep = set(data[:draw(st.integers(1, 3))])
            rows = [r for k, r in enumerate(rows) if k not in data or k in keep]
            data = sorted(keep)
        elif how == "empty":
            rows = [r for k, r in enumerate(rows) if k not in data]
            data = []
    return "\n".join(",".join(r) for r in rows) + "\n"


def _token(value: str, d: Path, inputs: list[str]) -> str:
    return {"OUT/": f"{d}/out.csv/", "LONG": f"{d}/{'n' * 300}.csv", "NL": f"{d}/a\nb.csv", "DIR": str(d),
            "INPUT": inputs[0] if inputs else str(d), "NODIR": f"{d}/no-such-folder/out.csv",
            "UNDERFILE": f"{d}/poses.csv/out.csv", "DIRFILE": f"{d}/poses.csv"}.get(value, value)


#: The slow commands (about a second each) are drawn less often, to keep the fuzz within CI time.
SLOW = ("observability", "identify", "identify-indicators", "plan", "info", "info-symmetric")


def _weighted(names):
    return [n for n in sorted(names) for _ in range(1 if n in SLOW else 3)]


def _fresh(base: Path, tmp_path_factory, name: str) -> tuple[Path, list[str], list[str]]:
    d = tmp_path_factory.mktemp("run")
    shutil.copytree(base, d, dirs_exist_ok=True)
    args = [a.replace("{}", str(d)) for a in templates()[name]]
    inputs = [a for a in args[1:] if a.startswith(str(d)) and Path(a).is_file()]
    return d, args, inputs


FUZZ = fuzz_settings(90)


@FUZZ
@given(st.sampled_from(_weighted(templates())), st.sampled_from(["file", "file", "file", "arguments"]), st.data())
def test_fuzz_every_command(base, tmp_path_factory, name, how, data):
    """One input file broken (YAML numbers, names, structure; CSV cells and rows), or the
    argument list (an argument dropped, an option added)."""
    d, args, inputs = _fresh(base, tmp_path_factory, name)
    if how == "file" and inputs:
        path = Path(data.draw(st.sampled_from(inputs)))
        text = path.read_text(encoding="utf-8")
        edit = yaml_edit(text) if path.suffix == ".yaml" else csv_edit(text)
        path.write_text(data.draw(edit), encoding="utf-8")
    elif len(args) > 1:
        k = data.draw(st.integers(1, len(args) - 1))
        if data.draw(st.booleans()):
            del args[k]
        else:
            args.insert(k, data.draw(st.sampled_from(["--bogus", "-o", "--seed", "--json", "--setup"])))
    before = snapshot(d)
    check_contract(invoke(args, d), d, before, args)


@FUZZ
@given(st.sampled_from(_weighted(t for t in templates() if t != "machines")), st.data())
def test_fuzz_option_values(base, tmp_path_factory, name, data):
    """One value on the command line (an option's value or an argument) replaced: negative,
    zero, nan, inf, 1e308, empty, a path ending in '/', an input file, a folder, a 300-byte
    name, a newline, a broken 'symmetric:' spec."""
    d, args, inputs = _fresh(base, tmp_path_factory, name)
    slots = [i for i in range(1, len(args)) if not args[i].startswith("-") or args[i][1:2].isdigit()]
    numeric = [i for i in slots if NUMERIC.fullmatch(args[i])]  # counts, seeds, sizes, poses: the dense part
    k = data.draw(st.sampled_from(numeric if numeric and data.draw(st.booleans()) else slots))
    args[k] = _token(data.draw(NUMERIC_TOKENS if k in numeric else TOKENS), d, inputs)
    before = snapshot(d)
    check_contract(invoke(args, d), d, before, args)


OUTPUT_SLOTS = {  # command line, the option whose value is replaced (added when missing)
    "ik": "-o", "fk": "-o", "simulate": "-o", "simulate-random": "--save-real", "identify": "--report",
    "identify-indicators": "-o", "verify": "-o", "export-hal": "-o", "export-json": "-o", "plan": "-o",
    "demo": "-o", "reproduce": "-o"}


@fuzz_settings(40)
@given(st.sampled_from(sorted(OUTPUT_SLOTS)), st.data())
def test_fuzz_bad_output_locations(base, tmp_path_factory, name, data):
    """Every output of every command given an impossible location: refused before anything
    is read, computed or written (exit 2, one line, no file)."""
    extra = {"demo": ["demo", "-o", "X"], "reproduce": ["reproduce", "paper2-table5", "--quick", "-o", "X"]}
    if name in extra:
        d = tmp_path_factory.mktemp("run")
        shutil.copytree(base, d, dirs_exist_ok=True)
        args, inputs = list(extra[name]), [str(d / "poses.csv")]
    else:
        d, args, inputs = _fresh(base, tmp_path_factory, name)
    option = OUTPUT_SLOTS[name]
    if option not in args:
        args += [option, "X"]
    bad = BAD_FOLDERS if option == "--report" or name == "demo" else BAD_FILES
    where = data.draw(st.sampled_from([b for b in bad if not (b == "INPUT" and name in extra)]))
    args[args.index(option) + 1] = _token(where, d, inputs)
    before = snapshot(d)
    res = invoke(args, d)
    check_contract(res, d, before, args)
    assert res.exit_code == 2, (args, res.output)


# -- files read by one rule ------------------------------------------------------------------------

VALUES = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr), st.integers(-10**9, 10**9).map(str),
                   st.sampled_from(["nan", "inf", "-inf", "1e308", "-0", "1_0", "none", "off", "", "abc"]))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["base_radius", "platform_radius", "base_separation", "platform_separation",
                                           "phase", "offset", "stroke", "u_joint_tilt", "s_joint_tilt",
                                           "leg_diameter"]), VALUES), min_size=1, max_size=3))
def test_symmetric_specs_give_a_finite_machine_or_an_error(items):
    """(Old: 'symmetric:base_radius=nan' built a machine of nan joints.)"""
    spec = "symmetric:" + ",".join(f"{k}={v}" for k, v in items)
    try:
        m = load_machine(spec)
    except PkmcalError as exc:
        assert "\n" not in str(exc) and str(exc).startswith(f"machine '{spec}'"), str(exc)
        return
    assert np.all(np.isfinite(m.params)) and np.all(np.isfinite(m.home_pose)), spec
    assert m.platform_radius > 0 and np.all(np.abs(m.params) <= MAX_MAGNITUDE), spec


@settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.integers(0, 13), st.integers(0, 14), st.one_of(st.floats(allow_nan=False).map(repr),
                                                         st.sampled_from(["1e308", "-1e308", "1e7", "9e5"])))
def test_measurements_hold_plausible_numbers(base, tmp_path, row, column, cell):
    """Every value a fit gets from a measurement file is within ±1e6 (mm, degrees), or the
    file is refused at that cell. (Old: one reading of 1e308 'calibrated' with chi2 = inf.)"""
    from pkmcal.io.measurements import load_measurements

    lines = (base / "meas_fp.csv").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("lambda1")) + 1 + row
    parts = lines[k].split(",")
    parts[column] = cell
    lines[k] = ",".join(parts)
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    try:
        meas = load_measurements(tmp_path / "m.csv", stewart_prototype(), builtin_setup("full-pose-paper1"))
    except PkmcalError as exc:
        assert f"m.csv, line {k + 1}" in str(exc), str(exc)
        return
    for values in (meas.actuators, meas.readings, meas.commanded):
        assert np.all(np.abs(np.where(np.isfinite(values), values, np.inf)) <= MAX_MAGNITUDE)

LEGS = """\
  - {base: [-152.5, 0, 0], platform: [-60.622, 35, 0], offset: OFFSET, stroke: [0, 50]}
  - {base: [-132.068, -76.25, 0], platform: [-35, -60.622, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, -132.068, 0], platform: [0, -70, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [132.068, -76.25, 0], platform: [70, 0, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [76.25, 132.068, 0], platform: [60.622, 35, 0], offset: 305.0, stroke: [0, 50]}
  - {base: [0, 152.5, 0], platform: [-35, 60.622, 0], offset: 305.0, stroke: [0, 50]}
"""


def _machine_text(offset: str) -> str:
    return "name: m\nlegs:\n" + LEGS.replace("OFFSET", offset)


@st.composite
def plain_numbers(draw) -> tuple[str, object]:
    """A plain YAML scalar for a leg offset, and what YAML 1.2's core schema reads it as (a
    number, or ``str`` for text): the oracle is the construction, not a YAML library. An
    integer written with a leading zero is refused whatever the readers make of it (the
    documented rule: ``010`` is 8 to YAML 1.1, 10 to YAML 1.2); its oracle is ``None``."""
    n = draw(st.integers(1, 999_999))
    kind = draw(st.sampled_from(["decimal", "leading-zero", "float", "exponent", "hex", "octal-1.2", "binary",
                                 "underscore", "base-60", "word"]))
    if kind == "decimal":
        text = draw(st.sampled_from(["", "+"])) + str(n)
        return text, float(n)
    if kind == "leading-zero":
        return "0" * draw(st.integers(1, 2)) + str(n), None
    if kind == "float":
        text = f"{n}.{draw(st.integers(0, 999))}"
        return text, float(text)
    if kind == "exponent":
        text = f"{n}{draw(st.sampled_from(['', '.', '.5']))}{draw(st.sampled_from(['e', 'E']))}" \
               f"{draw(st.sampled_from(['', '+', '-']))}{draw(st.integers(0, 2))}"
        return text, float(text)
    if kind == "hex":
        return f"0x{n:X}", float(n)
    if kind == "octal-1.2":
        return f"0o{n:o}", float(n)
    if kind == "binary":
        return f"0b{n:b}", str
    if kind == "underscore":
        return f"{n // 1000}_{n % 1000:03d}", str
    if kind == "base-60":
        return f"{n // 60}:{n % 60:02d}", str
    return draw(st.sampled_from(["yes", "no", "on", "off", "y", "n"])), str


@settings(max_examples=200, deadline=None)
@given(plain_numbers())
def test_yaml_numbers_mean_the_same_to_every_reader(case):
    """A number in a machine file is read as YAML 1.2 reads it, and only when a YAML 1.1
    reader (PyYAML) does not read another number from the same text; otherwise the file is
    refused with its line. (Old: '0305' loaded as 197, '5:05' as 305: YAML 1.1.)"""
    text, yaml12 = case
    machine_text = _machine_text(text)
    yaml11 = yaml.safe_load(machine_text)["legs"][0]["offset"]
    same_meaning = yaml12 not in (str, None) and (isinstance(yaml11, str) or float(yaml11) == yaml12)
    plausible = same_meaning and 0 <= yaml12 <= MAX_MAGNITUDE  # a length >= 0 (0: genhexkins) within ±1e6 mm
    try:
        loaded = float(machine_from_text(machine_text, "m.yaml").offset[0])
    except PkmcalError as exc:
        assert str(exc).startswith("m.yaml, line 3: "), str(exc)
        assert not plausible, f"{text!r} (YAML 1.2: {yaml12}, YAML 1.1: {yaml11!r}) was refused: {exc}"
        return
    assert plausible and loaded == yaml12, f"{text!r} loaded as {loaded} (YAML 1.2: {yaml12}, 1.1: {yaml11!r})"


NOT_NUMBERS = st.sampled_from(["true", "false", "True", "'0.01'", '"10"', "'1e-3'", "{a: 1}", ".nan", ".inf",
                               "-.inf", "1e308", "yes", "0x"])


SETUP_FIELDS = {"sensor": "sensor: indicators", "indicators": "indicators: [[40, 0], [-20, 34.641], [-20, -34.641]]",
                "plane_offset": "plane_offset: 10.0", "zero": "zero: [0, 0, 0]",
                "noise": "noise: {reading: 0.01, actuator: 0.005}", "free": "free: [zero1, zero2]"}


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(st.sampled_from(["plane_offset: V", "noise: {reading: V, actuator: 0.005}",
                        "noise: {reading: 0.01, actuator: V}", "zero: [0, V, 0]",
                        "indicators: [[40, 0], [V, 34.641], [-20, -34.641]]", "free: [V, zero1]"]),
       NOT_NUMBERS)
def test_setup_values_are_never_coerced(tmp_path, line, value):
    """A setup value that is not a finite, plausible number is refused, never converted; a
    parameter freed twice is refused. (Old: 'true' loaded as 1.0, '0.01' as 0.01, 'free:
    [zero1, zero1]' accepted.)"""
    key = line.split(":")[0]
    p = tmp_path / "s.yaml"
    good = "zero1" if key == "free" else "1.5"
    p.write_text("\n".join({**SETUP_FIELDS, key: line.replace("V", good)}.values()) + "\n")
    if key != "free":
        load_setup(p)  # the same line with a number loads
    p.write_text("\n".join({**SETUP_FIELDS, key: line.replace("V", value)}.values()) + "\n")
    with pytest.raises(PkmcalError, match=r"s.yaml, line \d+: "):
        load_setup(p)


# -- silently wrong before -----------------------------------------------------------------------

@pytest.mark.parametrize("written, yaml11, yaml12", [("0305", "197", "305"), ("010", "8", "10"),
                                                     ("5:05", "305", "text"), ("1_000", "1000", "text"),
                                                     ("0b11", "3", "text")])
def test_yaml11_numbers_are_refused(written, yaml11, yaml12):
    # Old: PyYAML's YAML 1.1 rules: 'offset: 0305' loaded as 197 mm, '010' as 8, '5:05' as 305.
    with pytest.raises(Exception) as info:
        machine_from_text(_machine_text(written), "m.yaml")
    msg = str(info.value)
    assert msg.startswith("m.yaml, line 3: ") and f"'{written}'" in msg and yaml11 in msg, msg
    assert (yaml12 in msg) if yaml12 != "text" else ("YAML 1.2 for text" in msg)


@pytest.mark.parametrize("written, value", [("305", 305.0), ("3.05e2", 305.0), ("0x131", 305.0), ("0o461", 305.0),
                                            ("+305", 305.0), ("305.", 305.0), ("'305'", None), (".inf", None),
                                            (".nan", None), ("true", None)])
def test_yaml12_numbers(written, value):
    """YAML 1.2 core-schema numbers load (3.05e2 was a string for PyYAML); quoted numbers,
    booleans and non-finite values are refused where a length is needed."""
    if value is None:
        with pytest.raises(Exception, match="m.yaml, line 3: legs"):
            machine_from_text(_machine_text(written), "m.yaml")
    else:
        assert machine_from_text(_machine_text(written), "m.yaml").offset[0] == value


def test_yaml_writer_quotes_what_either_reader_would_not_read_as_text():
    m = load_machine("stewart-prototype")
    for name in ("1e3", "0o17", "yes", "0305", "5:05", "2024-05-01", "true", "null", ".inf"):
        text = machine_to_text(m.with_params(m.params, name=name))
        assert machine_from_text(text, "m.yaml").name == name
        assert yaml.safe_load(text)["name"] == name  # a YAML 1.1 reader reads the same text


def test_setup_numbers_follow_yaml12(tmp_path):
    p = tmp_path / "s.yaml"
    p.write_text("sensor: indicators\nindicators: [[40, 0], [-20, 34.641], [-20, -34.641]]\nplane_offset: 010\n"
                 "noise: {reading: 1e-2, actuator: 0.005}\n")
    with pytest.raises(Exception, match=r"s.yaml, line 3: '010' .* octal number 8 .* write 10"):
        load_setup(p)
    p.write_text(p.read_text().replace("010", "10"))
    s = load_setup(p)  # 1e-2 (a string to YAML 1.1, coerced before) is the number 0.01
    assert s.sensor.plane_offset == 10.0 and s.noise.reading_std[0] == 0.01


@pytest.mark.parametrize("line", ['name: "x\\nsetp genhexkins.base.0.x 999"', 'description: "a\\rb"',
                                  'description: "a\\u2028b"', 'name: "tab\\tname"'])
def test_control_characters_in_names_are_refused(line):
    # Old: a newline in name: or description: was kept, and became a live 'setp' line in the
    # HAL export and broke the simulate CSV header.
    text = "legs:\n" + LEGS.replace("OFFSET", "305") + line + "\n"
    with pytest.raises(Exception, match=r"m.yaml, line 8: (name|description): holds a control character"):
        machine_from_text(text, "m.yaml")


def test_planar_and_setup_descriptions_are_one_line(tmp_path, base):
    text = (base / "planar.yaml").read_text().replace("name: planar-3dof-4act", 'name: "p\\nq"')
    with pytest.raises(Exception, match="name: holds a control character"):
        machine_from_text(text, "p.yaml")
    p = tmp_path / "s.yaml"
    p.write_text('sensor: position\ndescription: "a\\nb"\nnoise: {reading: 0.01, actuator: 0.005}\n')
    with pytest.raises(Exception, match=r"s.yaml, line 2: key 'description': holds a control character"):
        load_setup(p)


def test_hal_export_is_safe_by_construction():
    """Even a machine built in Python with a newline in its name and a 3 kB description ending
    in a backslash: no injected line, every line under halcmd's 1024-byte buffer."""
    from pkmcal.io.export_linuxcnc import linuxcnc_hal

    m = stewart_prototype()
    import dataclasses

    evil = dataclasses.replace(m, name="x\nsetp genhexkins.base.0.x 999\r",
                               description="é" * 1500 + "\nsetp genhexkins.platform.0.x 1\\")
    text = linuxcnc_hal(evil)
    live = [line for line in text.splitlines() if not line.startswith("#")]
    assert live == [line for line in linuxcnc_hal(m).splitlines() if not line.startswith("#")]
    assert len(live) == 36 and all(line.startswith("setp genhexkins.") for line in live)
    assert max(len(line.encode("utf-8")) for line in text.splitlines()) < 1024
    assert text.count("\n") == len(text.splitlines())


def test_csv_comments_and_cells_cannot_add_lines(tmp_path, base):
    # Old: simulate's comment line named the poses file as given: a path with a newline
    # ended the comment and its tail became the CSV header.
    text = format_table({"x": [1.0], "s": np.array(["a\nb"], dtype=object)},
                        comments=["poses a\nx,y,z\n1,2,3", "p\u2028q\x0bz"], units_comment=True)
    assert text.splitlines() == ["# units: length=mm, angle=deg", "# poses a\\nx,y,z\\n1,2,3", "# p\\u2028q\\x0bz",
                                 "x,s", "1.0,a\\nb"]
    d = tmp_path / "a\nb"
    d.mkdir()
    shutil.copy(base / "poses.csv", d / "poses.csv")
    res = run("simulate", base / "machine.yaml", "--real", base / "real.yaml", "--setup", base / "ind.yaml",
              "--poses", d / "poses.csv", "-o", tmp_path / "m.csv")
    assert res.exit_code == 0, res.output
    lines = (tmp_path / "m.csv").read_text().splitlines()
    header = next(line for line in lines if not line.startswith("#"))
    assert header.startswith("lambda1,") and len(lines) == len((tmp_path / "m.csv").read_text().split("\n")) - 1


def test_absurd_reading_is_refused(tmp_path, base):
    # Old: one reading of 1e308 'calibrated': exit 0, chi2 = inf, nominal values with
    # ordinary-looking standard deviations.
    lines = (base / "meas_fp.csv").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("lambda1")) + 3
    cells_ = lines[k].split(",")
    cells_[7] = "1e308"
    lines[k] = ",".join(cells_)
    (tmp_path / "m.csv").write_text("\n".join(lines) + "\n")
    res = run("identify", base / "machine.yaml", tmp_path / "m.csv", "--setup", base / "fp.yaml", "-o",
              tmp_path / "cal.yaml")
    assert_user_error(res, f"m.csv, line {k + 1}, column 'y'", "1e+308 mm is beyond ±1e+06 mm")
    assert not (tmp_path / "cal.yaml").exists()


@pytest.mark.parametrize("command", ["verify", "simulate", "identifiability", "observability", "plan"])
def test_absurd_pose_is_refused(tmp_path, base, command):
    # Old (found by the fuzz): a held-out pose at x = 1e308 mm gave 'invalid value
    # encountered in divide' and a table of the poses that remained.
    lines = (base / "poses.csv").read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("x,")) + 1
    lines[k] = "1e308" + lines[k][lines[k].index(","):]
    p = tmp_path / "p.csv"
    p.write_text("\n".join(lines) + "\n")
    args = {"verify": ("verify", base / "cal.yaml", "--real", base / "real.yaml", "--poses", p),
            "simulate": ("simulate", base / "machine.yaml", "--real", base / "real.yaml", "--setup", base / "ind.yaml",
                         "--poses", p),
            "identifiability": ("identifiability", base / "machine.yaml", "--setup", base / "ind.yaml", "--poses", p),
            "observability": ("observability", base / "machine.yaml",
                              *(("--poses", p) if _has_option("observability", "--poses") else (p,)),
                              "--setup", base / "ind.yaml"),
            "plan": ("plan", base / "machine.yaml", "--setup", base / "ind.yaml", "--candidates", p, "-o",
                     tmp_path / "o.csv")}[command]
    assert_user_error(run(*args), f"p.csv, line {k + 1}, column 'x': 1e+308 mm is beyond ±1e+06 mm")


@pytest.mark.parametrize("spec, why", [
    ("base_radius=nan", "is not a finite number"), ("base_radius=inf", "is not a finite number"),
    ("base_radius=0", "is not a radius of at least 0.001 mm"), ("platform_radius=-5", "is not a radius"),
    ("platform_radius=4e-219", "is not a radius"), ("offset=1e308", "beyond ±1e+06"),
    ("stroke=0", "is not a stroke of at least 0.001 mm"),
    ("u_joint_tilt=200", "tilt limit in (0, 180]"), ("base_separation=130", "[0, 120)"),
    ("base_radius=1,base_radius=2", "given twice"), ("offset=none", "cannot be none"),
    ("base_radius=1_0", "is not a number")])
def test_symmetric_values_are_checked(spec, why):
    # Old: 'symmetric:base_radius=nan' built a machine of nan joints (and 'info' printed it).
    assert_user_error(run("info", f"symmetric:{spec}"), why)


@pytest.mark.parametrize("value, why", [("true", "got true; true/false is not a number"),
                                        ("'0.01'", "got '0.01'; it is quoted text"), (".nan", "finite"),
                                        ("1e308", "beyond ±1e+06")])
def test_setup_values_are_not_coerced(tmp_path, base, value, why):
    # Old: 'plane_offset: true' loaded as 1.0 and '0.01' (quoted) as 0.01.
    p = tmp_path / "s.yaml"
    p.write_text("sensor: indicators\nindicators: [[40, 0], [-20, 34.641], [-20, -34.641]]\n"
                 f"plane_offset: {value}\nnoise: {{reading: 0.01, actuator: 0.005}}\n")
    assert_user_error(run("identifiability", base / "machine.yaml", "--setup", p, "--poses", base / "poses.csv"),
                      "s.yaml, line 3: key 'plane_offset'", why)


def test_setup_free_names_each_parameter_once(tmp_path, base):
    # Old: 'free: [zero1, zero1]' was accepted.
    p = tmp_path / "s.yaml"
    p.write_text((base / "ind.yaml").read_text() + "free: [zero1, zero1]\n")
    assert_user_error(run("identifiability", base / "machine.yaml", "--setup", p, "--poses", base / "poses.csv"),
                      "key 'free': 'zero1' is listed twice")


# -- tracebacks before ---------------------------------------------------------------------------

def test_platform_joints_at_the_origin(tmp_path, base):
    # Old: ZeroDivisionError in planning/candidates.py (platform radius 0).
    import dataclasses

    save_machine(dataclasses.replace(stewart_prototype(), platform=np.zeros((6, 3)), name="flat"), tmp_path / "z.yaml")
    res = run("plan", tmp_path / "z.yaml", "--setup", base / "ind.yaml", "--margin", "0.1", "-o", tmp_path / "p.csv")
    assert_user_error(res, f"machine 'flat' (from {tmp_path / 'z.yaml'})",
                      "every platform joint is at the platform origin")
    assert not (tmp_path / "p.csv").exists()


@pytest.mark.parametrize("param", ["L3", "rho12"])
def test_planar_link_of_length_zero(tmp_path, base, param):
    # Old: numpy.linalg.LinAlgError (singular matrix) in 'plan' and 'simulate'.
    text = re.sub(rf"\b{param}: [0-9.]+", f"{param}: 0.0", (base / "planar.yaml").read_text())
    (tmp_path / "p.yaml").write_text(text)
    line = next(k for k, s in enumerate(text.splitlines(), 1) if s.strip().startswith(f"{param}:"))
    res = run("simulate", tmp_path / "p.yaml", "--real", tmp_path / "p.yaml", "--setup", base / "planar_setup.yaml",
              "--poses", base / "planar_poses.csv")
    assert_user_error(res, f"p.yaml, line {line}: parameters.{param}: 0.0 mm is not a link length")


def test_identify_json_without_degrees_of_freedom(tmp_path, base):
    # Old: as many residuals as free parameters: chi2/dof = nan in the JSON, a ValueError
    # traceback, exit 1, after the calibrated file had been written (and 'export --format
    # json' of that file failed the same way on its 'reduced_chi2: .nan').
    lines = (base / "meas_ind.csv").read_text().splitlines()
    first = next(k for k, s in enumerate(lines) if s.startswith("lambda1"))
    (tmp_path / "m.csv").write_text("\n".join(lines[:first + 3]) + "\n")  # 2 poses: 6 readings, 6 offsets
    res = run("identify", base / "machine.yaml", tmp_path / "m.csv", "--setup", base / "ind.yaml", "-o",
              tmp_path / "cal.yaml", "--free", "L0_1,L0_2,L0_3,L0_4,L0_5,L0_6", "--json")
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 2:  # a fit without degrees of freedom may be refused: then nothing is written
        assert_user_error(res)
        assert not (tmp_path / "cal.yaml").exists()
        return
    _strict_json(res.stdout)
    assert json.loads(res.stdout)["reduced_chi2"] is None
    cal = yaml.safe_load((tmp_path / "cal.yaml").read_text())
    assert cal["calibration"]["reduced_chi2"] is None
    exported = run("export", tmp_path / "cal.yaml", "--format", "json")
    assert exported.exit_code == 0, exported.output
    _strict_json(exported.stdout)


@pytest.mark.parametrize("args", [
    ("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
     "--poses", "POSES", "--seed", "-1"),
    ("plan", "stewart-prototype", "--setup", "indicators-prototype", "-o", "OUT", "--seed", "-3"),
    ("info", "--seed", "-1"), ("reproduce", "paper2-table5", "--quick", "--seed", "-2"), ("demo", "--seed", "-1"),
])
def test_negative_seed_is_a_usage_error(tmp_path, base, args):
    # Old: ValueError traceback from numpy.random.default_rng.
    args = [str(base / "poses.csv") if a == "POSES" else str(tmp_path / "o.csv") if a == "OUT" else a for a in args]
    assert_user_error(run(*args), "--seed", "-")
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("value", ["1e308", "nan", "inf", "-1"])
def test_random_errors_must_be_a_finite_size(tmp_path, base, value):
    # Old: --random-errors 1e308: OverflowError traceback ('high - low range exceeds valid bounds').
    res = run("simulate", base / "machine.yaml", "--random-errors", value, "--setup", base / "fp.yaml",
              "--poses", base / "poses.csv", "-o", tmp_path / "m.csv")
    assert_user_error(res, "--random-errors")
    assert not (tmp_path / "m.csv").exists()


def test_uncreatable_report_folder_writes_nothing(tmp_path, base):
    # Old: the calibrated file was written, then os.mkdir raised NotADirectoryError.
    (tmp_path / "file").write_text("x")
    res = run("identify", base / "machine.yaml", base / "meas_fp.csv", "--setup", base / "fp.yaml", "-o",
              tmp_path / "cal.yaml", "--report", tmp_path / "file" / "rep")
    assert_user_error(res, "--report", "is not a folder")
    assert sorted(os.listdir(tmp_path)) == ["file"]


def test_uncreatable_demo_folder(tmp_path):
    (tmp_path / "file").write_text("x")
    assert_user_error(run("demo", "-o", tmp_path / "file" / "out"), "-o", "is not a folder")
    assert sorted(os.listdir(tmp_path)) == ["file"]


def test_setup_name_longer_than_the_file_system_allows(base):
    # Old: OSError traceback ('File name too long') from Path.exists.
    res = run("identifiability", base / "machine.yaml", "--setup", "s" * 300, "--poses", base / "poses.csv")
    assert_user_error(res, "does not exist and is not a built-in setup")


def test_identify_never_writes_a_machine_file_it_cannot_load(tmp_path, base):
    # Old: 12 poses x 3 readings for 36 free parameters interpolate the noise; the fit
    # wandered to a leg offset of 10 km and the file was written (it no longer loads).
    lines = (base / "meas_ind.csv").read_text().splitlines()
    (tmp_path / "m.csv").write_text("\n".join(lines[:-2]) + "\n")
    res = run("identify", base / "machine.yaml", tmp_path / "m.csv", "--setup", base / "ind.yaml", "-o",
              tmp_path / "cal.yaml", "--fix", "auto")
    assert res.exit_code in (0, 2), res.output
    if res.exit_code == 0:
        load_machine(tmp_path / "cal.yaml")
    else:
        assert_user_error(res)
        assert not (tmp_path / "cal.yaml").exists()


def test_ik_is_written_in_blocks_with_the_same_bytes(tmp_path, base, monkeypatch):
    """``ik`` computes and writes _IK_BLOCK poses at a time (a million poses peaked at 5.1 GB
    when done at once): with blocks of 5 poses the output is byte for byte the one-block
    output, to a file and to standard output."""
    from pkmcal.cli import kinematics_cmds

    res = run("ik", base / "machine.yaml", "--poses", base / "poses.csv", "-o", tmp_path / "one.csv")
    assert res.exit_code == 0
    monkeypatch.setattr(kinematics_cmds, "_IK_BLOCK", 5)
    assert run("ik", base / "machine.yaml", "--poses", base / "poses.csv", "-o", tmp_path / "blocks.csv").exit_code == 0
    assert (tmp_path / "blocks.csv").read_bytes() == (tmp_path / "one.csv").read_bytes()
    assert run("ik", base / "machine.yaml", "--poses", base / "poses.csv").stdout == (tmp_path / "one.csv").read_text()
    lines = (tmp_path / "one.csv").read_text().splitlines()
    assert sum(not s.startswith("#") for s in lines) == 15  # one header, 14 rows


def test_ik_error_after_the_first_block_writes_nothing(tmp_path, base, monkeypatch):
    from pkmcal.cli import kinematics_cmds

    monkeypatch.setattr(kinematics_cmds, "_IK_BLOCK", 5)
    text = (base / "poses.csv").read_text().splitlines()
    text[-1] = text[-1].replace(",", ",x", 1)
    (tmp_path / "p.csv").write_text("\n".join(text) + "\n")
    assert_user_error(run("ik", base / "machine.yaml", "--poses", tmp_path / "p.csv", "-o", tmp_path / "o.csv"), "is not a number")
    assert sorted(os.listdir(tmp_path)) == ["p.csv"]


# -- hygiene -------------------------------------------------------------------------------------

@pytest.mark.parametrize("args, fragment", [
    (("fk", "stewart-prototype"), "Missing argument 'LEGS.csv'"),
    (("fk", "stewart-prototype"), "(usage: cli fk [OPTIONS] MACHINE LEGS.csv"),
    (("fk", "stewart-prototype"), "see 'cli fk --help')"),
    (("ik", "stewart-prototype"), "Missing option '--poses'"),
    (("ik", "stewart-prototype", "--poses", "p.csv", "--bogus"), "No such option '--bogus'"),
    (("export", "stewart-prototype", "--format", "xml"), "'xml' is not one of 'linuxcnc', 'json'"),
    (("no-such-command",), "No such command 'no-such-command'"),
    (("--bogus",), "No such option '--bogus'"),
    (("plan", "stewart-prototype", "--setup", "indicators-prototype", "-o", "x.csv", "--margin", "nan"),
     "'nan' is not a finite number"),
])
def test_usage_errors_are_one_line(args, fragment):
    # Old: click's 3-4 line block (Usage: ..., Try ..., blank line, Error: ...).
    res = run(*args)
    assert_user_error(res, fragment)


def test_runtime_warnings_never_precede_the_error_line(monkeypatch):
    # Old: numpy RuntimeWarnings (overflow, invalid value) were printed before the error line.
    from pkmcal.cli import main
    from pkmcal.errors import PkmcalError

    @click.command("noisy")
    @click.option("--fail", is_flag=True)
    def noisy(fail):
        np.log(np.array([-1.0]))
        np.array([1e308]) * 10
        if fail:
            raise PkmcalError("the input is wrong")
        click.echo("done")

    monkeypatch.setitem(main.COMMANDS, "noisy", (__name__, "_noisy", "test"))
    monkeypatch.setattr(sys.modules[__name__], "_noisy", noisy, raising=False)
    res = run("noisy", "--fail")
    assert_user_error(res, "the input is wrong")
    res = run("noisy")
    assert res.exit_code == 0 and res.stdout == "done\n"
    warnings_ = res.stderr.splitlines()
    assert len(warnings_) == 2 and all(w.startswith("pkmcal: warning: numerical problem") for w in warnings_)
    assert "RuntimeWarning" not in res.stderr


def test_killed_write_leaves_a_temporary_that_the_next_write_removes(tmp_path):
    # Old: 'kill -9' during a write left the hidden temporary file behind for good.
    target = tmp_path / "out.csv"
    code = ("import os, signal, sys\nfrom pkmcal.io.atomic import atomic_writer\n"
            "with atomic_writer(sys.argv[1]) as fh:\n    fh.write('partial')\n    fh.flush()\n"
            "    os.kill(os.getpid(), signal.SIGKILL)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    proc = subprocess.run([sys.executable, "-c", code, str(target)], env=env, capture_output=True)
    assert proc.returncode == -signal.SIGKILL
    left = [n for n in os.listdir(tmp_path) if TEMP.fullmatch(n)]
    assert len(left) == 1 and not target.exists()
    (tmp_path / ".out.csv.notours.tmp").write_text("keep")      # not our pattern
    (tmp_path / ".other.csv.pkmcal-00000000-1-abc.tmp").write_text("keep")  # another target
    host = re.search(r"pkmcal-([0-9a-f]{8})-", left[0]).group(1)
    live = f".out.csv.pkmcal-{host}-{os.getppid()}-abcdefgh.tmp"         # a live writer of this host
    (tmp_path / live).write_text("in progress")
    write_table(target, {"x": [1.0]})
    assert target.read_text().endswith("x\n1.0\n")
    assert sorted(os.listdir(tmp_path)) == sorted([".out.csv.notours.tmp", ".other.csv.pkmcal-00000000-1-abc.tmp",
                                                   live, "out.csv"])
    old = os.path.getmtime(tmp_path / live)
    assert remove_stale_temporaries(target, now=old + 23 * 3600) == []
    assert remove_stale_temporaries(target, now=old + 25 * 3600) == [live]  # any writer, after a day


def test_atomic_writer_removes_its_temporary_on_error(tmp_path):
    with pytest.raises(ZeroDivisionError):
        with atomic_writer(tmp_path / "o.txt") as fh:
            fh.write("x")
            1 / 0
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("command", [
    ("ik", "stewart-prototype", "--poses", "POSES", "-o"), ("fk", "stewart-prototype", "LEGS", "-o"),
    ("export", "stewart-prototype", "--format", "json", "-o"),
    ("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
     "--poses", "POSES", "-o"),
    ("plan", "stewart-prototype", "--setup", "indicators-prototype", "-o"),
    ("identify", "stewart-prototype", "MEAS", "--setup", "IND", "-o"),
    ("verify", "stewart-prototype-real", "--real", "stewart-prototype-real", "--poses", "POSES", "-o"),
])
@pytest.mark.parametrize("out, why", [("out.csv/", ("cannot write output file", "ends with a separator")),
                                      ("", ("''",)), ("missing/out.csv", ("cannot write output file", "the folder")),
                                      (".", ("is a folder",))])
def test_bad_output_paths_are_refused_before_anything_runs(tmp_path, base, monkeypatch, command, out, why):
    # Old: '-o out.csv/' wrote out.csv; '-o missing/out.csv' failed after the computation.
    monkeypatch.chdir(tmp_path)
    files = {"POSES": base / "poses.csv", "LEGS": base / "legs.csv", "MEAS": base / "meas_ind.csv",
             "IND": base / "ind.yaml"}
    res = run(*[files.get(a, a) for a in command], out)
    assert_user_error(res, *why)
    assert os.listdir(tmp_path) == []


def test_reproduce_refuses_an_empty_output_path(tmp_path, monkeypatch):
    # Old: 'reproduce NAME -o ""' ran the reproduction, exited 0 and wrote nothing.
    monkeypatch.chdir(tmp_path)
    assert_user_error(run("reproduce", "paper2-table5", "--quick", "-o", ""), "''")
    assert os.listdir(tmp_path) == []


def test_post_load_errors_name_the_file(tmp_path, base):
    # Old: "the real machine 'stewart-prototype-real' reaches none of ..." without the file,
    # whose 'name:' may be anything (here the name of a built-in).
    import dataclasses

    far = dataclasses.replace(load_machine(base / "real.yaml"), stroke=np.tile([0.0, 1.0], (6, 1)))  # too short
    save_machine(far, tmp_path / "far.yaml")
    res = run("simulate", base / "machine.yaml", "--real", tmp_path / "far.yaml", "--setup", base / "ind.yaml",
              "--poses", base / "poses.csv", "-o", tmp_path / "m.csv")
    assert_user_error(res, f"machine 'stewart-prototype-real' (from {tmp_path / 'far.yaml'})")
    res = run("verify", tmp_path / "far.yaml", "--real", "stewart-prototype-real", "--poses", base / "poses.csv")
    assert res.exit_code in (0, 2)
    if res.exit_code == 2:  # both machines have one name: the message says which is which
        assert_user_error(res)
        assert str(tmp_path / "far.yaml") in res.stderr and "built-in" in res.stderr, res.stderr


def test_yaml_line_map_is_unchanged_by_the_yaml12_resolver():
    data, lines = parse_yaml("a: 1\nb:\n  - 0o17\n  - 1e3\nc: yes\n")
    assert data == {"a": 1, "b": [15, 1000.0], "c": "yes"} and lines[("b", 1)] == 4


def test_regression_unit_conversion_overflow_is_an_error_naming_the_line(tmp_path):
    """Fuzz finding (PYTHONHASHSEED=41, --hypothesis-seed=13): a reading of 1e308 in metres
    overflowed to inf when converted to mm and surfaced as a numerical warning; it is an
    input error naming the line and column."""
    legs = tmp_path / "legs.csv"
    legs.write_text("# units: length=m\nlambda1,lambda2,lambda3,lambda4,lambda5,lambda6\n"
                    "0.02,0.02,0.02,0.02,0.02,0.02\n1e308,0.02,0.02,0.02,0.02,0.02\n")
    res = CliRunner().invoke(cli, ["fk", "stewart-prototype", str(legs), "-o", str(tmp_path / "out.csv")])
    assert res.exit_code == 2 and "line 4" in res.output and "lambda1" in res.output, res.output
    assert "encountered in" not in res.output and not (tmp_path / "out.csv").exists()
