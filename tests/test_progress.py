"""Progress bars (:mod:`pkmcal.progress`): on a terminal a bar on standard error; with a
redirected standard output, or ``--quiet``, nothing; machine-readable output stays clean.

The terminal runs use pseudo-terminals (the ``pty`` module, with a window size as a real
terminal has) for standard output and standard error, each its own, so that what the
command wrote to each can be told apart. ``PKMCAL_PROGRESS_DELAY=0`` makes the bar appear at
the first update, so the tests do not depend on how fast the machine is.
"""

from __future__ import annotations

import io
import json
import os
import select
import subprocess
import sys

import numpy as np
import pytest

import pkmcal
from pkmcal.progress import ProgressBar, bars_enabled

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="pseudo-terminals are POSIX")

PLAN = ["plan", "stewart-prototype", "--setup", "indicators-prototype", "--n-poses", "15", "--n-candidates", "300",
        "--algorithm", "cuckoo", "--seed", "1"]


def _pty():
    import fcntl
    import pty
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    return master, slave


def run(args, cwd, *, stdout_tty=True, stderr_tty=True):
    """Run ``python -m pkmcal.cli.main ARGS`` with standard output / error on their own
    pseudo-terminals (or pipes); return (exit code, stdout text, stderr text)."""
    src = os.path.dirname(os.path.dirname(os.path.abspath(pkmcal.__file__)))   # the pkmcal under test
    env = {**os.environ, "PKMCAL_PROGRESS_DELAY": "0",
           "PYTHONPATH": os.pathsep.join([src, *filter(None, [os.environ.get("PYTHONPATH")])])}
    ends, readers = [], {}
    for name, tty in (("out", stdout_tty), ("err", stderr_tty)):
        master, slave = _pty() if tty else os.pipe()
        ends.append(slave)
        readers[master] = name
    proc = subprocess.Popen([sys.executable, "-m", "pkmcal.cli.main", *args], cwd=cwd, stdin=subprocess.DEVNULL,
                            stdout=ends[0], stderr=ends[1], env=env)
    for fd in ends:
        os.close(fd)
    data = {"out": b"", "err": b""}
    open_fds = list(readers)
    while open_fds:
        ready, _, _ = select.select(open_fds, [], [], 300)
        assert ready, "the command printed nothing for 300 s"
        for fd in ready:
            try:
                chunk = os.read(fd, 1 << 16)
            except OSError:                      # a pseudo-terminal whose other end closed
                chunk = b""
            if chunk:
                data[readers[fd]] += chunk
            else:
                open_fds.remove(fd)
                os.close(fd)
    code = proc.wait(timeout=300)
    return code, data["out"].decode(errors="replace"), data["err"].decode(errors="replace")


def test_plan_on_a_terminal_shows_a_bar_on_stderr_only(tmp_path):
    code, out, err = run([*PLAN, "-o", "poses.csv"], tmp_path)
    assert code == 0, err
    assert "plan: selection (cuckoo):" in err and "|" in err     # the tqdm bar, on standard error
    assert "selection (cuckoo)" not in out and "wrote poses.csv" in out
    assert err.split("\r")[-1].strip() == "" and err.split("\r")[-2].strip() == ""   # the bar is removed at the end


def test_quiet_or_redirected_stdout_means_no_bar(tmp_path):
    code, out, err = run([*PLAN, "-o", "q.csv", "--quiet"], tmp_path)
    assert code == 0 and err == "" and "wrote q.csv" in out
    code, out, err = run([*PLAN, "-o", "p.csv"], tmp_path, stdout_tty=False)   # e.g. pkmcal plan ... | tee
    assert code == 0 and err == "", err
    assert "wrote p.csv" in out


def test_csv_on_stdout_stays_a_clean_table(tmp_path):
    """``plan`` without -o writes the CSV to standard output: no bar, no summary in it."""
    code, out, err = run(PLAN, tmp_path, stdout_tty=False, stderr_tty=False)
    assert code == 0, err
    lines = out.splitlines()
    header = next(k for k, line in enumerate(lines) if not line.startswith("#"))
    assert lines[header].startswith("x,y,z,a,b,c,lambda1")
    assert len(lines) - header - 1 == 15 and all(line.count(",") == 11 for line in lines[header:])
    assert "safety margin" in err and "|" not in err.replace("safety margin", "")


def test_json_stays_valid_with_a_bar_on_the_terminal(tmp_path):
    code, out, err = run(["reproduce", "paper1-table1", "--quick", "--json"], tmp_path)
    assert code == 0, err
    assert "reproduce paper1-table1:" in err and "runs" in err
    # numba's colorama resets a terminal's colours at exit ("\x1b[0m"; on a terminal only)
    assert json.loads(out.replace("\r\n", "\n").replace("\x1b[0m", ""))["name"] == "paper1-table1"


def test_bars_need_both_streams_on_a_terminal(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stdout", Tty())
    monkeypatch.setattr(sys, "stderr", Tty())
    assert bars_enabled() and not bars_enabled(quiet=True)
    monkeypatch.setattr(sys, "stdout", io.StringIO())
    assert not bars_enabled()


def test_bar_stages_counts_and_notes(monkeypatch):
    class Tty(io.StringIO):
        def isatty(self):
            return True

    err = Tty()
    monkeypatch.setattr(sys, "stdout", Tty())
    monkeypatch.setattr(sys, "stderr", err)
    monkeypatch.setenv("PKMCAL_PROGRESS_DELAY", "0")
    with ProgressBar("job") as bar:
        assert bar.stage("first") is bar
        bar(3, 10)
        assert bar._bar.n == 3 and bar._bar.total == 10
        bar.stage("second")
        assert bar._bar.n == 0 and bar._bar.total is None
        bar(1, 4)
        bar.note("a line above the bar")
        assert bar._bar.desc.startswith("job: second")
    assert bar._bar is None
    text = err.getvalue()
    assert "job: first: 3/10" in text and "a line above the bar\n" in text


def test_disabled_bar_is_silent_and_imports_nothing():
    """Under pytest standard output is not a terminal: every call is a no-op; in a fresh
    interpreter tqdm is not imported (a bar is never shown)."""
    bar = ProgressBar("job")
    assert not bar.enabled and bar.stage("x") is None
    bar(1, 2)
    bar.close()
    code = ("import sys; from pkmcal.progress import ProgressBar\n"
            "b = ProgressBar('x'); b.stage('s'); b(1, 2); b.close()\n"
            "print('tqdm' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"


def test_plan_reports_its_stages_and_the_selection_steps():
    from pkmcal.io.setup_file import builtin_setup
    from pkmcal.mechanisms.library import stewart_prototype
    from pkmcal.planning.plan import plan_poses

    stages, steps = [], []

    def announce(stage):
        stages.append(stage)
        return (lambda done, total: steps.append((done, total))) if stage.startswith("selection") else None

    plan_poses(stewart_prototype(), builtin_setup("indicators-prototype"), 15, n_candidates=200, seed=0,
               progress=announce)
    assert stages == ["workspace box", "candidates", "planning model", "selection (default)"]
    done = [d for d, _ in steps]
    assert steps and done == sorted(done) and all(d <= t for d, t in steps)


def test_simulation_in_chunks_is_the_simulation_at_once(monkeypatch):
    """Chunked simulation (progress after each chunk) gives the same readings, kept and
    dropped poses as one pass over all poses."""
    import pkmcal.identification.simulation as sim
    from pkmcal.io.setup_file import builtin_setup
    from pkmcal.mechanisms.library import stewart_prototype, stewart_prototype_real

    nominal, real, setup = stewart_prototype(), stewart_prototype_real(), builtin_setup("indicators-prototype")
    rng = np.random.default_rng(5)
    poses = np.tile(nominal.home_pose, (23, 1)) + rng.uniform(-1, 1, (23, 6)) * [30, 30, 15, 0.15, 0.15, 0.4]
    whole = sim.simulate_campaign(nominal, real, setup, poses, rng=3)
    calls = []
    monkeypatch.setattr(sim, "CHUNK_POSES", 7)
    parts = sim.simulate_campaign(nominal, real, setup, poses, rng=3, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(7, 23), (14, 23), (21, 23), (23, 23)]
    assert whole.dropped and parts.dropped == whole.dropped        # some poses are out of reach
    np.testing.assert_array_equal(parts.kept, whole.kept)
    np.testing.assert_allclose(parts.sensor_readings, whole.sensor_readings, rtol=0, atol=1e-12)
    np.testing.assert_allclose(parts.actuator_readings, whole.actuator_readings, rtol=0, atol=1e-12)


def test_every_reproduction_reports_its_runs():
    import inspect

    from pkmcal.reproduce import REPRODUCTIONS, run_reproduction

    for name, (fn, _) in REPRODUCTIONS.items():
        assert "progress" in inspect.signature(fn).parameters, name
    calls = []
    run_reproduction("paper3-case2", quick=True, progress=lambda d, t: calls.append((d, t)))
    assert calls == [(1, 1)]
