"""``pkmcal demo`` end to end: the README's main-job command in a fresh folder.

One run of the command (a subprocess, as a user runs it) feeds every test here; a second,
in-process run with the same seed must write the same bytes.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import pkmcal_subprocess_env

from pkmcal.cli.main import cli
from pkmcal.conventions import poses_from_file_units
from pkmcal.demo import DemoConfig, run_demo
from pkmcal.errors import PkmcalError
from pkmcal.identification.verification import verify
from pkmcal.io.machine_file import load_machine
from pkmcal.io.tables import read_table


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("fresh")
    # the timeout guards against a hang, it is no speed test: the demo takes ~40 s alone and
    # several times that on a loaded shared machine
    proc = subprocess.run([sys.executable, "-m", "pkmcal.cli.main", "demo"], cwd=cwd, capture_output=True,
                          text=True, timeout=1800, check=False, env=pkmcal_subprocess_env())
    assert proc.returncode == 0, proc.stderr[-3000:]
    return cwd, cwd / "pkmcal-demo", proc


def _micrometres(line: str) -> list[float]:
    """The lengths of a summary line in µm (printed as mm, or µm below 0.1 mm)."""
    return [float(v) * (1000.0 if unit == "mm" else 1.0) for v, unit in re.findall(r"(\d+\.\d+) (mm|µm)", line)]


def test_demo_prints_progress_and_summary(demo_run):
    _, out, proc = demo_run
    for k, step in enumerate(("plan", "simulate", "identify", "verify", "export", "report"), start=1):
        assert f"[{k}/6] {step}" in proc.stderr
    lines = proc.stdout.splitlines()
    pos = next(line for line in lines if line.strip().startswith("position error"))
    before, after = _micrometres(pos)[:2]
    assert before > 1000.0 and after < 50.0  # µm: millimetres of error become tens of micrometres
    assert any(line.startswith("Report:") and "pkmcal-demo/report.html" in line for line in lines)


def test_demo_writes_its_files(demo_run):
    _, out, _ = demo_run
    for name in ("report.html", "stewart-prototype-calibrated.yaml", "stewart-prototype-calibrated.hal",
                 "calibration.json", "measurements.csv", "planned-poses.csv", "held-out-poses.csv", "setup.yaml",
                 "parameters.svg", "parameters.png", "held-out.svg", "error-map.svg", "machine-poses.svg"):
        assert (out / name).is_file(), name
    hal = (out / "stewart-prototype-calibrated.hal").read_text()
    assert hal.count("setp genhexkins.base.") == 18 and hal.count("setp genhexkins.platform.") == 18


def test_exported_machine_reproduces_the_verification(demo_run):
    """Independent check through the files: the calibrated YAML, commanded at the held-out
    poses of the CSV, brings the real machine as close as the summary says."""
    _, out, _ = demo_run
    summary = json.loads((out / "calibration.json").read_text())
    calibrated = load_machine(str(out / "stewart-prototype-calibrated.yaml"))
    nominal, real = load_machine("stewart-prototype"), load_machine("stewart-prototype-real")
    held = poses_from_file_units(read_table(out / "held-out-poses.csv", ("x", "y", "z", "a", "b", "c"))[
        ["x", "y", "z", "a", "b", "c"]])
    v = verify(calibrated, real, held, nominal)
    m = v.common
    rms_after = float(np.sqrt(np.mean(v.after.position[m] ** 2)))
    rms_before = float(np.sqrt(np.mean(v.before.position[m] ** 2)))
    head = summary["headline_mm_rad"]
    assert rms_after == pytest.approx(head["position_rms_after"], rel=1e-9)
    assert rms_before == pytest.approx(head["position_rms_before"], rel=1e-9)
    # The calibrated parameters are closer to the truth than the nominal ones, overall.
    assert np.linalg.norm(calibrated.params - real.params) < 0.5 * np.linalg.norm(nominal.params - real.params)


def test_demo_json_summary_is_the_printed_one_in_mm_and_degrees(demo_run):
    """``demo --json``'s numbers (:func:`pkmcal.cli.demo_cmd.summary_json`) are the run's
    headline (calibration.json: mm and rad, and its own mm/deg copy), keyed as ``verify
    --json``'s, and round to what the text summary printed."""
    from types import SimpleNamespace

    from pkmcal.cli.demo_cmd import summary_json

    _, out, proc = demo_run
    written = json.loads((out / "calibration.json").read_text())
    result = SimpleNamespace(headline=written["headline_mm_rad"], notes=(), files={"report": out / "report.html"},
                             verification=SimpleNamespace(to_dict=lambda: {"used": 97}))
    d = summary_json(result)
    assert d["held_out_poses"] == 97 and d["files"] == {"report": str(out / "report.html")} and d["notes"] == []
    for when in ("before", "after"):
        assert set(d[when]) == {"position_rms_mm", "position_max_mm", "orientation_rms_deg", "orientation_max_deg"}
        for key, value in d[when].items():
            quantity, stat, _ = key.split("_")
            assert value == pytest.approx(written["headline_mm_deg"][f"{quantity}_{stat}_{when}"], rel=1e-12)
    line = next(line for line in proc.stdout.splitlines() if line.strip().startswith("position error"))
    rms_before_um, rms_after_um = _micrometres(line)[:2]
    # printed with 4 significant digits: within half a unit of the 4th digit
    assert rms_before_um == pytest.approx(1000.0 * d["before"]["position_rms_mm"], rel=5e-4)
    assert rms_after_um == pytest.approx(1000.0 * d["after"]["position_rms_mm"], rel=5e-4)


def test_demo_is_byte_identical_for_the_same_seed(demo_run, tmp_path):
    _, out, _ = demo_run
    again = run_demo(DemoConfig(out=str(tmp_path / "again")))
    first = sorted(p.name for p in out.iterdir())
    assert sorted(p.name for p in again.out.iterdir()) == first
    for name in first:
        assert (out / name).read_bytes() == (again.out / name).read_bytes(), name


def test_demo_report_renders_in_chromium(demo_run, tmp_path):
    if shutil.which("chromium") is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    from test_report_chromium import check_rendered_report

    shot = check_rendered_report(demo_run[1] / "report.html", tmp_path)
    assert shot.stat().st_size > 100_000


def test_demo_refuses_bad_requests(tmp_path):
    with pytest.raises(PkmcalError, match="candidates"):
        DemoConfig(n_poses=50, n_candidates=10)
    taken = tmp_path / "file"
    taken.write_text("x")
    with pytest.raises(PkmcalError, match="not a folder"):
        run_demo(DemoConfig(out=str(taken)))
    res = CliRunner().invoke(cli, ["demo", "-o", str(taken)])
    assert res.exit_code == 2 and "not a folder" in res.output and res.exception is not None
    assert "Traceback" not in res.output
