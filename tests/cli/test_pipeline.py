"""The measurement-day pipeline on the command line: ``simulate`` → ``identify --report`` →
``export``; same seed, same bytes; an output never replaces an input; a killed ``identify``
leaves no output file behind (outputs are written atomically, after the computation)."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import pkmcal_subprocess_env

from pkmcal.cli.main import cli
from pkmcal.identification.simulation import simulate_campaign
from pkmcal.io import load_machine
from pkmcal.io.measurements import save_measurements
from pkmcal.io.setup_file import builtin_setup
from pkmcal.io.tables import format_table

POSE_NAMES = ("x", "y", "z", "a", "b", "c")
HALF = np.array([8.0, 8.0, 4.0, 2.0, 2.0, 4.0])  # mm, deg: all reachable by both machines


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def ok(res):
    assert res.exit_code == 0, res.output
    return res


def write_poses(path, n, seed):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-1, 1, (n, 6)) * HALF
    p[:, :3] += load_machine("stewart-prototype").home_pose[:3]
    path.write_text(format_table({k: p[:, i] for i, k in enumerate(POSE_NAMES)}))


SIM = ("simulate", "stewart-prototype", "--real", "stewart-prototype-real", "--setup", "indicators-prototype")
IDENT = ("identify", "stewart-prototype", "--setup", "indicators-prototype")


def test_same_seed_same_bytes_and_report(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # relative paths: they are written into the outputs' comments
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1798761600")  # the calibration record's date
    write_poses(tmp_path / "poses.csv", 30, 1)
    ok(run(*SIM, "--poses", "poses.csv", "--seed", "7", "-o", "m1.csv"))
    ok(run(*SIM, "--poses", "poses.csv", "--seed", "7", "-o", "m2.csv"))
    ok(run(*SIM, "--poses", "poses.csv", "--seed", "8", "-o", "m3.csv"))
    m1 = (tmp_path / "m1.csv").read_bytes()
    assert m1 == (tmp_path / "m2.csv").read_bytes()
    assert m1 != (tmp_path / "m3.csv").read_bytes()  # the seed matters
    outs = []
    for k in (1, 2):
        res = ok(run(*IDENT, "m1.csv", "-o", "cal.yaml", "--report", f"rep{k}"))
        assert f"wrote cal.yaml and rep{k}/report.html" in res.stdout
        outs.append((tmp_path / "cal.yaml").read_bytes())
    # the same bytes but for the calibration record's command line (--report rep1 / rep2)
    assert outs[0].replace(b"--report rep1", b"--report rep2") == outs[1]
    names = sorted(os.listdir(tmp_path / "rep1"))
    assert "report.html" in names and any(n.endswith(".svg") for n in names)
    assert names == sorted(os.listdir(tmp_path / "rep2"))
    for n in names:
        assert (tmp_path / "rep1" / n).read_bytes() == (tmp_path / "rep2" / n).read_bytes(), n
    page = (tmp_path / "rep1" / "report.html").read_text(encoding="utf-8")
    assert "stewart-prototype" in page and "m1.csv" in page and "fk-residual" in page
    for fmt in ("linuxcnc", "json"):
        ok(run("export", "cal.yaml", "--format", fmt, "-o", f"a.{fmt}"))
        ok(run("export", "cal.yaml", "--format", fmt, "-o", f"b.{fmt}"))
        assert (tmp_path / f"a.{fmt}").read_bytes() == (tmp_path / f"b.{fmt}").read_bytes()


def test_outputs_never_replace_inputs(tmp_path):
    write_poses(tmp_path / "poses.csv", 20, 2)
    ok(run(*SIM, "--poses", tmp_path / "poses.csv", "-o", tmp_path / "meas.csv"))
    before = {p: (tmp_path / p).read_bytes() for p in ("poses.csv", "meas.csv")}
    cases = [
        (*SIM, "--poses", tmp_path / "poses.csv", "-o", tmp_path / "poses.csv"),
        (*IDENT, tmp_path / "meas.csv", "-o", tmp_path / "meas.csv"),
        (*IDENT, tmp_path / "meas.csv", "-o", tmp_path / "cal.yaml", "--report", tmp_path / "meas.csv"),
        ("verify", "stewart-prototype", "--real", "stewart-prototype-real", "--poses", tmp_path / "poses.csv",
         "-o", tmp_path / "poses.csv"),
        ("ik", "stewart-prototype", "--poses", tmp_path / "poses.csv", "-o", tmp_path / "poses.csv"),
    ]
    for args in cases:
        res = run(*args)
        assert res.exit_code == 2, (args, res.output)
        err = res.stderr.strip()
        assert err.startswith("pkmcal: error: ") and "\n" not in err
        assert "never overwrites" in err or "not a folder" in err, err
        assert not (tmp_path / "cal.yaml").exists()
    assert {p: (tmp_path / p).read_bytes() for p in before} == before


def _cpu_seconds(pid: int) -> float:
    """CPU time (user + system, all threads) the process has used, from /proc/<pid>/stat."""
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _campaign_file(path, n: int) -> None:
    nominal, real = load_machine("stewart-prototype"), load_machine("stewart-prototype-real")
    setup = builtin_setup("indicators-prototype")
    rng = np.random.default_rng(5)
    p = rng.uniform(-1, 1, (n, 6)) * HALF
    p[:, :3] += nominal.home_pose[:3]
    p[:, 3:] = np.deg2rad(p[:, 3:])
    save_measurements(path, simulate_campaign(nominal, real, setup, p, rng=6).measurements, nominal, setup)


def _identify_cmd(tmp_path, meas, report=True):
    return [sys.executable, "-m", "pkmcal.cli.main", *IDENT, str(meas), "-o", str(tmp_path / "cal.yaml"),
            *(["--report", str(tmp_path / "rep")] if report else [])]


@pytest.mark.skipif(not os.path.exists("/proc/self/stat"), reason="needs /proc to measure the child's CPU time")
def test_killed_identify_leaves_no_output(tmp_path):
    """SIGKILL during a long identification (60 000 poses): no calibrated file, no report, no
    temporary file. (Files are written after the fit, each to a temporary file renamed over
    the target.)

    The kill must land inside the fit, whatever the machine and its load, so it is timed by
    the child's CPU time (not wall time: on a loaded machine a fixed sleep fired during the
    start-up and tested nothing) against the CPU time of a 50-pose run without report measured
    here: start-up and a trivial fit cost c (~2.3 s on a 2-core Xeon, 2026-12), the 60 000-pose
    run reaches its calibrated file at ~4.5 c, so the kill at 2.5 c is inside reading and
    fitting."""
    small, big = tmp_path / "small", tmp_path / "big"
    small.mkdir()
    big.mkdir()
    _campaign_file(small / "meas.csv", 50)
    _campaign_file(big / "meas.csv", 60000)
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    done = subprocess.run(_identify_cmd(small, small / "meas.csv", report=False), capture_output=True, text=True,
                          env=pkmcal_subprocess_env(), check=False)
    assert done.returncode == 0, done.stderr
    now = resource.getrusage(resource.RUSAGE_CHILDREN)
    kill_at = 2.5 * (now.ru_utime + now.ru_stime - used.ru_utime - used.ru_stime)
    before = sorted(os.listdir(big))
    proc = subprocess.Popen(_identify_cmd(big, big / "meas.csv"), stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True, env=pkmcal_subprocess_env())
    try:
        deadline = time.monotonic() + 900.0
        while proc.poll() is None and time.monotonic() < deadline:
            try:
                if _cpu_seconds(proc.pid) >= kill_at:
                    break
            except (FileNotFoundError, ProcessLookupError):
                break
            time.sleep(0.02)
        assert proc.poll() is None, (f"identify finished before it had used {kill_at:.1f} s of CPU "
                                     f"(make the campaign larger): {proc.stderr.read()!r}")
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert sorted(os.listdir(big)) == before  # no cal.yaml, no .cal.yaml.*.tmp, no rep/


@pytest.mark.parametrize("bad", ["rep_file"])
def test_report_folder_must_be_a_folder(tmp_path, bad):
    write_poses(tmp_path / "poses.csv", 20, 3)
    ok(run(*SIM, "--poses", tmp_path / "poses.csv", "-o", tmp_path / "meas.csv"))
    (tmp_path / bad).write_text("x")
    res = run(*IDENT, tmp_path / "meas.csv", "-o", tmp_path / "cal.yaml", "--report", tmp_path / bad)
    assert res.exit_code == 2 and "is not a folder" in res.stderr
    assert not (tmp_path / "cal.yaml").exists() and (tmp_path / bad).read_text() == "x"


def test_report_without_commanded_poses(tmp_path):
    """A measurement file without cmd_x..cmd_c (as from a real data logger): the report's
    pose cloud is the nominal FK of the leg readings, one pose per row."""
    write_poses(tmp_path / "poses.csv", 45, 4)
    ok(run(*SIM, "--poses", tmp_path / "poses.csv", "-o", tmp_path / "meas.csv"))
    lines = (tmp_path / "meas.csv").read_text().splitlines()
    header = lines[[k for k, s in enumerate(lines) if not s.startswith("#")][0]].split(",")
    keep = [k for k, h in enumerate(header) if not h.startswith("cmd_")]
    (tmp_path / "legs_dials.csv").write_text("\n".join(
        s if s.startswith("#") else ",".join(s.split(",")[k] for k in keep) for s in lines) + "\n")
    res = ok(run(*IDENT, tmp_path / "legs_dials.csv", "-o", tmp_path / "cal.yaml", "--report", tmp_path / "rep",
                 "--json"))
    import json

    j = json.loads(res.stdout)
    assert j["report"] == str(tmp_path / "rep" / "report.html") and j["n_poses"] == 45
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    assert "legs_dials.csv</td>" in page and 'poses used</td><td class="l">45 (dropped 0)' in page
