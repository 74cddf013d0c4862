"""The HTML report in headless Chromium: no script errors, the plots are laid out and painted,
and a deep link opens a call's exact window. Skipped only when no Chromium is installed
(`apt-get install -y chromium`)."""

from __future__ import annotations

import io
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from reports.commands import report_main
from tests.reports.png import count_color, read_png

CHROMIUM = next((p for p in (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")) if p), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install -y chromium)")

ORANGE = (0xF2, 0x8E, 0x2B)  # the second series colour: recap's bars in the success chart


def _chromium(tmp: Path, *args: str) -> subprocess.CompletedProcess:
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", f"--user-data-dir={tmp / 'profile'}",
           "--virtual-time-budget=5000", *args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def page(run_a, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("html")
    rc = report_main([str(run_a), "--out", str(out), "--format", "html", "--episodes", "A-recap-t2-42,A-react-t6-42"], stdout=io.StringIO(), stderr=io.StringIO())
    assert rc == 0
    return out / "report.html"


def test_page_runs_without_errors_and_lays_out_every_plot(page, tmp_path):
    dom = _chromium(tmp_path, "--dump-dom", page.as_uri() + "#call-ep-A-recap-t2-42-3").stdout
    body = re.search(r"<body[^>]*>", dom).group(0)
    assert 'data-report-ready="1"' in body
    assert "data-js-errors" not in body
    assert 'data-plots-rendered="7"' in body  # all 7 charts have a size and marks
    # the deep link opened call 3's window: exactly messages 0, 1, 6, 7 in order
    panel = re.search(r'<div class="window-panel" id="ep-A-recap-t2-42-window">(.*?)</div>', dom, re.S).group(1)
    assert panel.startswith("<p>Window of call 3: 4 messages (0-1,6-7); reply stored as message 8</p>")
    assert re.findall(r'data-seq="(\d+)"', panel) == ["0", "1", "6", "7"]
    assert "Done: prepare onion. Observation: You hold the onion." in panel


def test_screenshot_shows_the_plots(page, tmp_path):
    shot = tmp_path / "shot.png"
    _chromium(tmp_path, "--hide-scrollbars", "--window-size=1280,2400", "--force-device-scale-factor=0.5", f"--screenshot={shot}", page.as_uri())
    image = read_png(shot)
    assert image[:2] == (640, 1200)
    with_plots = count_color(image, ORANGE)
    # the same page without its SVG plots: the orange pixels were the bars
    bare = tmp_path / "bare.html"
    bare.write_text(re.sub(r"<svg .*?</svg>", "", page.read_text(), flags=re.S))
    shot2 = tmp_path / "bare.png"
    _chromium(tmp_path, "--hide-scrollbars", "--window-size=1280,2400", "--force-device-scale-factor=0.5", f"--screenshot={shot2}", bare.as_uri())
    without = count_color(read_png(shot2), ORANGE)
    assert with_plots >= 1500, with_plots
    assert without == 0


def test_script_errors_are_caught(page, tmp_path):
    broken = tmp_path / "broken.html"
    broken.write_text(page.read_text().replace("</main>", "</main><script>undefinedFunction();</script>"))
    body = re.search(r"<body[^>]*>", _chromium(tmp_path, "--dump-dom", broken.as_uri()).stdout).group(0)
    assert re.search(r'data-js-errors="[^"]*undefinedFunction[^"]*"', body)
