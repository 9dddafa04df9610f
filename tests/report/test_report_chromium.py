"""The HTML report renders in a real browser: headless Chromium (Debian's ``chromium``).

Skipped when ``chromium`` is not on the PATH. Console messages are read from Chromium's
log (``--enable-logging=stderr``: lines ``INFO:CONSOLE...``); a control page with a
deliberate console error shows that the check can fail.
"""

from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = shutil.which("chromium")
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (apt-get install chromium)")

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync")


def _chromium(args: list[str], profile: Path) -> subprocess.CompletedProcess:
    # a guard against a hang, not a speed test (a loaded machine renders several times slower)
    return subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={profile}", *args], capture_output=True, text=True,
                          timeout=600, check=False)


def render_in_chromium(html: Path, tmp: Path) -> tuple[str, list[str], Path]:
    """Render ``html``: (serialised DOM, console messages, screenshot path in ``tmp``)."""
    url = html.resolve().as_uri()
    dom_run = _chromium(["--enable-logging=stderr", "--v=0", "--dump-dom", url], tmp / "profile-dom")
    console = [line for line in dom_run.stderr.splitlines() if ":CONSOLE" in line]
    shot = tmp / "report.png"
    shot_run = _chromium([f"--screenshot={shot}", "--window-size=1280,4000", "--enable-logging=stderr", "--v=0", url],
                         tmp / "profile-shot")
    console += [line for line in shot_run.stderr.splitlines() if ":CONSOLE" in line]
    assert dom_run.returncode == 0, dom_run.stderr[-2000:]
    assert shot_run.returncode == 0 and shot.exists(), shot_run.stderr[-2000:]
    return dom_run.stdout, console, shot


def check_rendered_report(html: Path, tmp: Path) -> Path:
    """Assert the report renders without console errors and shows every figure; returns
    the screenshot."""
    dom, console, shot = render_in_chromium(html, tmp)
    assert console == [], console
    source = html.read_text(encoding="utf-8")
    figures = re.findall(r'<figure id="(fig-[^"]+)">', source)
    assert len(figures) >= 6
    for fig in figures:
        block = re.search(rf'<figure id="{fig}">(.*?)</figure>', dom, re.S)
        assert block is not None, f"{fig} missing from the rendered DOM"
        assert re.search(r"<svg\b", block.group(1)), f"{fig} has no <svg> in the rendered DOM"
        assert "<path" in block.group(1) or "<image" in block.group(1), f"{fig} is empty"
    import matplotlib.image as mpimg

    img = mpimg.imread(shot)
    assert img.shape[0] == 4000 and img.shape[1] == 1280
    rgb = img[..., :3]
    # The page is not blank: a good part of the rows carry drawing (not uniform white).
    busy_rows = np.mean(rgb.std(axis=(1, 2)) > 0.02)
    assert busy_rows > 0.3, busy_rows
    # Colour is present (the figures), not only black text on white.
    assert np.mean(np.ptp(rgb, axis=2) > 0.2) > 0.001
    return shot


@needs_chromium
def test_console_errors_are_detected(tmp_path):
    page = tmp_path / "control.html"
    page.write_text('<!DOCTYPE html><html><body><p>x</p><script>console.error("pkmcal-control");'
                    "</script></body></html>", encoding="utf-8")
    _, console, _ = render_in_chromium(page, tmp_path)
    assert any("pkmcal-control" in line for line in console)


@needs_chromium
def test_report_renders_in_chromium(tmp_path):
    from test_report import make_report_data

    from pkmcal.report import write_report

    files = write_report(make_report_data(), tmp_path / "report")
    shot = check_rendered_report(files.html, tmp_path)
    assert shot.parent == tmp_path
