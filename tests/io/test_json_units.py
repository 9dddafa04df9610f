"""Every number in every JSON pkmcal prints or writes states its unit, by the one rule of
docs/conventions.md ("Units in JSON"):

* the key ends in a unit suffix (:data:`SUFFIXES`), which applies to everything under it;
* else a ``units`` object in the same or an enclosing object maps the key to its unit
  (``"1"`` for counts and dimensionless numbers);
* else the object has a ``unit`` string, the unit of its numbers.

Angles are degrees: a ``_rad`` key is allowed only beside its ``_deg`` twin (a deprecated
alias). The test runs every command with JSON output (``identify``, ``identifiability``,
``observability``, ``verify`` with ``--json``; ``export --format json``; ``reproduce
--json``; the demo's ``calibration.json``) and checks every numeric leaf.
Old behaviour: ``verify --json`` gave radians only, ``identify --json`` numbers such as
``cost`` and ``chi2`` without units, ``observability --json`` bare indices."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pkmcal.cli.main import cli
from pkmcal.io.tables import format_table
from pkmcal.mechanisms.library import stewart_prototype

SUFFIXES = ("_mm", "_deg", "_rad", "_percent", "_pct", "_s", "_arcsec", "_um", "_bytes")
POSE_NAMES = ("x", "y", "z", "a", "b", "c")


def uncovered(obj, path: str = "", units: dict | None = None, covered: bool = False) -> list[str]:
    """Paths of the numeric leaves of ``obj`` whose unit the rule does not state, and of
    ``_rad`` keys without a ``_deg`` twin."""
    units = dict(units or {})
    bad: list[str] = []
    if isinstance(obj, dict):
        if isinstance(obj.get("units"), dict):
            units.update(obj["units"])
        unit_here = isinstance(obj.get("unit"), str)
        for k, v in obj.items():
            if k in ("units", "unit"):
                continue
            here = f"{path}.{k}" if path else str(k)
            if isinstance(k, str) and k.endswith("_rad") and k[:-4] + "_deg" not in obj:
                bad.append(here + " (radians without a _deg twin)")
            cov = covered or (isinstance(k, str) and k.endswith(SUFFIXES)) or k in units
            if isinstance(v, (dict, list)):
                bad += uncovered(v, here, units, cov)
            elif _number(v) and not (cov or unit_here):
                bad.append(here)
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            if isinstance(v, (dict, list)):
                bad += uncovered(v, f"{path}[{i}]", units, covered)
            elif _number(v) and not covered:
                bad.append(f"{path}[{i}]")
    return bad


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def test_checker_itself():
    assert uncovered({"a_mm": 1, "b": 2, "units": {"c": "1"}, "c": [1, 2], "d": {"e": 3}}) == ["b", "d.e"]
    assert uncovered({"p": {"unit": "mm", "v": 1.0}, "q": {"x_rad": 1.0}}) == ["q.x_rad (radians without a _deg twin)"]
    assert uncovered({"units": {"n": "1"}, "sub": {"n": 4, "m_percent": {"z": 1}}}) == []


def run(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


def _poses_file(path, n=30, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 6)) * np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])
    p[:, :3] += stewart_prototype().home_pose[:3]
    path.write_text(format_table({k: p[:, i] for i, k in enumerate(POSE_NAMES)}))
    return path


@pytest.fixture(scope="module")
def hexapod_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("json")
    poses = _poses_file(d / "poses.csv")
    held = _poses_file(d / "held.csv", 10, 1)
    out = {}
    for setup in ("indicators-prototype", "full-pose-paper1"):
        meas = d / f"m-{setup}.csv"
        run("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", setup, "--poses", poses,
            "-o", meas)
        cal = d / f"cal-{setup}.yaml"
        out[setup] = json.loads(run("identify", "stewart-prototype", meas, "--setup", setup, "-o", cal,
                                    "--json").stdout)
        out[f"cal-{setup}"] = cal
    return d, poses, held, out


@pytest.mark.parametrize("setup", ["indicators-prototype", "full-pose-paper1"])
def test_identify_json(hexapod_files, setup):
    d = hexapod_files[3][setup]
    assert uncovered(d) == []
    assert all(p["unit"] in ("mm", "deg") for p in d["parameters"].values())


@pytest.mark.parametrize("setup", ["indicators-prototype", "full-pose-paper1", "laser-tracker"])
def test_identifiability_and_observability_json(hexapod_files, setup):
    _, poses, _, _ = hexapod_files
    assert uncovered(json.loads(run("identifiability", "stewart-prototype", "--setup", setup, "--poses", poses,
                                    "--json").stdout)) == []
    assert uncovered(json.loads(run("observability", "stewart-prototype", poses, "--setup", setup,
                                    "--json").stdout)) == []


def test_verify_json_degrees_and_deprecated_radians(hexapod_files):
    d, _, held, out = hexapod_files
    v = json.loads(run("verify", out["cal-indicators-prototype"], "--real", "stewart-prototype-real", "--poses", held,
                       "--nominal", "stewart-prototype", "--json").stdout)
    assert uncovered(v) == []
    for side in ("before", "after"):
        s = v[side]
        assert s["orientation_mean_deg"] == pytest.approx(np.rad2deg(s["orientation_mean_rad"]), rel=1e-12)
        assert s["tilt_max_deg"] == pytest.approx(np.rad2deg(s["tilt_max_rad"]), rel=1e-12)
        assert "position_mean_mm" in s                     # the contract
    v_only = json.loads(run("verify", out["cal-indicators-prototype"], "--real", "stewart-prototype-real", "--poses",
                            held, "--json").stdout)
    assert uncovered(v_only) == []


def test_export_json(hexapod_files):
    d, _, _, out = hexapod_files
    text = run("export", out["cal-full-pose-paper1"], "--format", "json", "-o", d / "cal.json")
    del text
    assert uncovered(json.loads((d / "cal.json").read_text())) == []


def test_planar_identify_and_verify_json(tmp_path):
    from pkmcal.mechanisms.planar import planar_3dof_4act

    m = planar_3dof_4act()
    rng = np.random.default_rng(2)
    x = m.sample_poses(25, rng, shrink=0.6)
    cols = {"x": x[:, 0], "y": x[:, 1], "phi": np.rad2deg(x[:, 2])}
    (tmp_path / "p.csv").write_text(format_table(cols))
    run("simulate", "planar-3dof-4act", "--random-errors", "0.2", "--save-real", tmp_path / "real.yaml",
        "--setup", "planar-tracker", "--poses", tmp_path / "p.csv", "-o", tmp_path / "m.csv")
    d = json.loads(run("identify", "planar-3dof-4act", tmp_path / "m.csv", "--setup", "planar-tracker",
                       "-o", tmp_path / "cal.yaml", "--json").stdout)
    assert uncovered(d) == []
    assert d["parameters"]["alpha1"]["unit"] == "deg"
    v = json.loads(run("verify", tmp_path / "cal.yaml", "--real", tmp_path / "real.yaml", "--poses", tmp_path / "p.csv",
                       "--setup", "planar-tracker", "--nominal", "planar-3dof-4act", "--json").stdout)
    assert uncovered(v) == []


@pytest.mark.parametrize("name", ["paper1-table1", "paper3-case2"])
def test_reproduce_json(name):
    assert uncovered(json.loads(run("reproduce", name, "--quick", "--json").stdout)) == []


def test_demo_calibration_json(tmp_path):
    from pkmcal.demo import DemoConfig, run_demo

    res = run_demo(DemoConfig(out=str(tmp_path / "demo"), n_poses=20, n_candidates=200, n_held_out=10,
                              error_map_points=3, png=False))
    assert uncovered(json.loads(res.files["json"].read_text())) == []
