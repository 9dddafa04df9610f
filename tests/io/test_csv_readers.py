"""Every CSV pkmcal writes is read by ``pandas.read_csv`` and ``csv.DictReader`` with their
default arguments into the documented columns, and its numbers read back bit-identical
(issue 11 item 10; docs/file-formats.md).

The files are made by the commands themselves (plan, ik, fk, simulate for a hexapod with
indicators and with a full-pose sensor and for a planar machine, demo, study), in one
folder. For each file: the header is the documented column list; pandas and csv see that
header and every row; each numeric cell pandas parses is the double ``float(cell)`` gives
(the inverse of the ``repr`` pkmcal writes), and pkmcal's own reader gives the same doubles.
With ``--units-comment`` the file starts with its units line, pkmcal still reads it, and
pandas reads it with ``comment='#'``.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.tables import read_table

POSE = ["x", "y", "z", "a", "b", "c"]
LAMBDA = [f"lambda{i}" for i in range(1, 7)]
CMD = [f"cmd_{c}" for c in POSE]


def run(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> dict[str, tuple[Path, list[str]]]:
    """name → (path, documented columns) of every kind of CSV the commands write."""
    d = tmp_path_factory.mktemp("csv")
    out: dict[str, tuple[Path, list[str]]] = {}
    run("plan", "stewart-prototype", "--setup", "indicators-prototype", "--n-poses", 15, "--n-candidates", 200,
        "--seed", 1, "-o", d / "poses.csv")
    out["plan"] = (d / "poses.csv", POSE + LAMBDA)
    run("ik", "stewart-prototype", "--poses", d / "poses.csv", "-o", d / "legs.csv")
    out["ik"] = (d / "legs.csv", POSE + [f"l{i}" for i in range(1, 7)] + LAMBDA + ["reachable"])
    (d / "far.csv").write_text("lambda1,lambda2,lambda3,lambda4,lambda5,lambda6\n" + "25,25,25,25,25,25\n"
                               + "-300,-300,-300,-300,-300,-300\n")
    run("fk", "stewart-prototype", d / "far.csv", "-o", d / "fk.csv")          # row 2: nan pose
    out["fk"] = (d / "fk.csv", POSE + ["converged", "iterations", "same_branch", "reachable"])
    run("fk", "stewart-prototype", d / "legs.csv", "-o", d / "fk-legs.csv")
    out["fk-legs"] = (d / "fk-legs.csv", out["fk"][1])
    run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype",
        "--poses", d / "poses.csv", "--seed", 2, "-o", d / "meas.csv")
    out["simulate-indicators"] = (d / "meas.csv", LAMBDA + ["d1", "d2", "d3"] + CMD)
    run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "full-pose-paper1",
        "--poses", d / "poses.csv", "--seed", 2, "--ignore-limit", "leg_collision", "-o", d / "meas-full.csv")
    out["simulate-full-pose"] = (d / "meas-full.csv", LAMBDA + POSE + CMD)
    run("plan", "planar-3dof-4act", "--setup", "planar-tracker", "--n-poses", 8, "--n-candidates", 80, "-o",
        d / "planar-poses.csv")
    out["plan-planar"] = (d / "planar-poses.csv", ["x", "y", "phi", "q1", "q2", "q3", "q4"])
    run("simulate", "planar-3dof-4act", "--random-errors", 0.5, "--setup", "planar-tracker", "--poses",
        d / "planar-poses.csv", "-o", d / "planar-meas.csv")
    out["simulate-planar"] = (d / "planar-meas.csv", ["q1", "q2", "q3", "q4", "px", "py", "cmd_x", "cmd_y", "cmd_phi"])
    run("demo", "-o", d / "demo", "--n-poses", 20, "--held-out", 5)
    out["demo-poses"] = (d / "demo" / "planned-poses.csv", None)
    out["demo-measurements"] = (d / "demo" / "measurements.csv", None)
    out["demo-held-out"] = (d / "demo" / "held-out-poses.csv", None)
    study = d / "study.yaml"
    study.write_text("name: tiny\nseed: 0\ntrials: 2\nmachines:\n  - nominal: stewart-prototype\n"
                     "    real: stewart-prototype-real\n    ignore_limits: [leg_collision]\n"
                     "setups:\n  - {setup: indicators-prototype, label: indicators}\n"
                     "plans:\n  - {algorithm: random, poses: [15]}\nmethods: [auto]\nheldout: {poses: 5}\n")
    run("study", study, "-o", d / "study", "--workers", 1, "--no-figures", "-q")
    out["study-trials"] = (d / "study" / "trials.csv", None)
    out["study-summary"] = (d / "study" / "summary.csv", None)
    return out


KINDS = ["plan", "ik", "fk", "fk-legs", "simulate-indicators", "simulate-full-pose", "plan-planar",
         "simulate-planar", "demo-poses", "demo-measurements", "demo-held-out", "study-trials", "study-summary"]


def _number(cell: str):
    try:
        return float(cell)
    except ValueError:
        return None


@pytest.mark.parametrize("kind", KINDS)
def test_pandas_and_csv_read_every_written_csv_with_defaults(written, kind):
    path, documented = written[kind]
    assert path.exists(), f"{kind}: {path} was not written"
    text = path.read_text(encoding="utf-8")
    first = text.splitlines()[0]
    assert not first.startswith("#"), f"{kind}: starts with a comment line"
    header = next(csv.reader([first]))
    if documented is not None:
        assert header == documented, kind
    frame = pd.read_csv(path)
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
        assert reader.fieldnames == header
    assert list(frame.columns) == header
    assert len(frame) == len(rows) == len(text.splitlines()) - 1
    assert all(None not in r and len(r) == len(header) for r in rows)     # no ragged row
    numeric = []
    for name in header:
        cells = [r[name] for r in rows]
        values = [_number(c) for c in cells]
        if all(v is not None for v in values):
            numeric.append(name)
            got = frame[name].to_numpy(dtype=float)
            want = np.array(values)
            same = (got == want) | (np.isnan(got) & np.isnan(want))
            assert same.all(), f"{kind}: column {name} differs from float(cell) in rows {np.flatnonzero(~same)[:5]}"
            # and the bits: pandas reads the shortest repr pkmcal writes back to the same double
            assert all(math.copysign(1, a) == math.copysign(1, b) for a, b in zip(got, want) if a == 0)
        else:
            assert frame[name].astype(str).tolist() == [c if c else "nan" for c in cells] or kind.startswith("study")
    assert numeric, f"{kind}: no numeric column"
    if documented is not None and kind != "fk":
        table = read_table(path, [n for n in numeric], kinds={})
        np.testing.assert_array_equal(table.values, frame[numeric].to_numpy(dtype=float))


def test_written_values_are_the_computed_doubles(written, tmp_path):
    """ik's leg lengths in the file are the doubles the machine computes, bit for bit."""
    from pkmcal.mechanisms.library import builtin_machine
    from pkmcal.io.tables import read_poses

    path, _ = written["ik"]
    m = builtin_machine("stewart-prototype")
    poses = read_poses(written["plan"][0], m)
    frame = pd.read_csv(path)
    np.testing.assert_array_equal(frame[[f"l{i}" for i in range(1, 7)]].to_numpy(), m.leg_lengths(poses))
    np.testing.assert_array_equal(frame[LAMBDA].to_numpy(), m.ik(poses))


@pytest.mark.parametrize("command", ["plan", "ik", "fk", "simulate"])
def test_units_comment_is_written_only_when_asked_and_still_read(written, tmp_path, command):
    d = tmp_path
    poses = written["plan"][0]
    args = {
        "plan": ["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n-poses", 15, "--n-candidates", 200,
                 "--seed", 1],
        "ik": ["ik", "stewart-prototype", "--poses", poses],
        "fk": ["fk", "stewart-prototype", written["ik"][0]],
        "simulate": ["simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup",
                     "indicators-prototype", "--poses", poses, "--seed", 2],
    }[command]
    plain_path = {"plan": written["plan"][0], "ik": written["ik"][0], "fk": written["fk-legs"][0],
                  "simulate": written["simulate-indicators"][0]}[command]
    run(*args, "-o", d / "c.csv", "--units-comment")
    text = (d / "c.csv").read_text()
    assert text.startswith("# units: length=mm, angle=deg\n# pkmcal ")
    assert text.endswith(plain_path.read_text())           # the same table after the comment lines
    frame = pd.read_csv(d / "c.csv", comment="#")
    pd.testing.assert_frame_equal(frame, pd.read_csv(plain_path))
    header = list(frame.columns)
    numeric = [h for h in header if h != "reachable"]
    np.testing.assert_array_equal(read_table(d / "c.csv", numeric, kinds={}).values,
                                  read_table(plain_path, numeric, kinds={}).values)
