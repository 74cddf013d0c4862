"""The HTML report in headless Chromium: no script errors, the plots are laid out and painted (no
legend over a bar, 0 % bars visible), and a deep link opens a call's exact window.

Part of the default suite. It uses the distribution's Chromium (``apt-get install -y chromium``;
``scripts/test.sh`` installs it; nothing is downloaded at run time). Without a Chromium the tests
FAIL with a message saying so; ``RECAP_SKIP_BROWSER=1`` is the explicit opt-out that skips them.
"""

from __future__ import annotations

import io
import os
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from pipeline.cli.report import report_main
from reports import svg
from reports.model import Plot, Report, Section
from reports.render_html import render_html
from tests.reports.png import count_color, read_png

OPT_OUT = "RECAP_SKIP_BROWSER"
NAMES = ("chromium", "chromium-browser", "google-chrome")
#: seconds one Chromium run may take (a cold start on a busy 2-core machine takes ~3 s)
TIMEOUT_S = 90

ORANGE = (0xF2, 0x8E, 0x2B)  # the second series colour: recap's bars in the success chart


def find_chromium() -> str | None:
    return next((p for p in (shutil.which(n) for n in NAMES) if p), None)


def browser_or_fail() -> str:
    """The browser's path; fails (never a silent skip) when there is none, unless opted out."""
    if os.environ.get(OPT_OUT) == "1":
        pytest.skip(f"{OPT_OUT}=1: the headless-browser check of the HTML report is switched off")
    path = find_chromium()
    if path is None:
        pytest.fail(
            f"no Chromium found (looked for {', '.join(NAMES)} on PATH): install the distribution's package "
            f"(apt-get install -y chromium; bash scripts/test.sh does) or set {OPT_OUT}=1 to skip this check",
            pytrace=False,
        )
    return path


@pytest.fixture(scope="module")
def chromium() -> str:
    return browser_or_fail()


def _run(chromium: str, tmp: Path, *args: str) -> subprocess.CompletedProcess:
    """One headless Chromium run with a fresh profile; fails with its stderr on error or timeout."""
    profile = tempfile.mkdtemp(prefix="profile-", dir=tmp)
    cmd = [
        chromium,
        "--headless",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-extensions",
        "--mute-audio",
        f"--user-data-dir={profile}",
        "--virtual-time-budget=5000",
    ]
    if os.geteuid() == 0:
        cmd.append("--no-sandbox")  # Chromium refuses to run as root inside its sandbox
    try:
        done = subprocess.run([*cmd, *args], capture_output=True, text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        pytest.fail(f"Chromium did not finish within {TIMEOUT_S} s: {' '.join(cmd + list(args))}", pytrace=False)
    if done.returncode != 0:
        pytest.fail(f"Chromium exited {done.returncode}: {done.stderr.strip()[-2000:]}", pytrace=False)
    return done


def _body(dom: str) -> str:
    m = re.search(r"<body[^>]*>", dom)
    assert m, f"no <body> in Chromium's DOM dump: {dom[:300]!r}"
    return m.group(0)


@pytest.fixture(scope="module")
def page(run_a, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("html")
    rc = report_main(
        [str(run_a), "--out", str(out), "--format", "html", "--episodes", "A-recap-t2-42,A-react-t6-42"],
        stdout=io.StringIO(),
        stderr=io.StringIO(),
    )
    assert rc == 0
    return out / "report.html"


def test_page_runs_without_errors_and_lays_out_every_plot(chromium, page, tmp_path):
    dom = _run(chromium, tmp_path, "--dump-dom", page.as_uri() + "#call-ep-A-recap-t2-42-3").stdout
    body = _body(dom)
    assert 'data-report-ready="1"' in body
    assert "data-js-errors" not in body
    n_plots = page.read_text().count('<svg xmlns="http://www.w3.org/2000/svg" class="chart"')
    assert n_plots >= 7
    assert f'data-plots-rendered="{n_plots}"' in body  # every chart has a size and marks
    assert 'data-legend-overlaps="0"' in body
    # the 0 % bars (react and the test double's react on ALFWorld, 0/1 each) are painted
    zeros = page.read_text().count('class="bar zero"')
    assert zeros >= 2
    assert f'data-zero-bars-visible="{zeros}"' in body
    # the deep link opened call 3's window: exactly messages 0, 1, 6, 7 in order
    panel = re.search(r'<div class="window-panel" id="ep-A-recap-t2-42-window">(.*?)</div>', dom, re.S).group(1)
    assert panel.startswith("<p>Window of call 3: 4 messages (0-1,6-7); reply stored as message 8</p>")
    assert re.findall(r'data-seq="(\d+)"', panel) == ["0", "1", "6", "7"]
    assert "Done: prepare onion. Observation: You hold the onion." in panel


def test_legend_of_twelve_arms_covers_no_bar_in_the_browser(chromium, tmp_path):
    """Real text widths: twelve long arm names, three splits, some 0 % bars."""
    arms = [f"recap [level_{i}+no_shortcut] · gpt-4o-mini" for i in range(12)]
    splits = ["robotouille/synchronous", "robotouille/asynchronous", "alfworld/valid_unseen"]
    values = {(s, a): (0.0 if i % 4 == 0 else 7.5 * i) for s in splits for i, a in enumerate(arms)}
    chart = svg.grouped_bars("Success", splits, arms, values, y_max=100, value_fmt=lambda v: f"{v:.1f}")
    html = tmp_path / "twelve.html"
    html.write_text(
        render_html(Report("twelve arms", [], [], [Section("s", "S", plots=[Plot("p", "P", chart, "success_by_split")])], {}))
    )
    body = _body(_run(chromium, tmp_path, "--dump-dom", html.as_uri()).stdout)
    assert 'data-plots-rendered="1"' in body
    assert 'data-legend-overlaps="0"' in body
    assert 'data-zero-bars-visible="9"' in body  # arms 0, 4, 8 in each of 3 splits


def test_screenshot_shows_the_plots(chromium, page, tmp_path):
    shot = tmp_path / "shot.png"
    _run(
        chromium,
        tmp_path,
        "--hide-scrollbars",
        "--window-size=1280,2400",
        "--force-device-scale-factor=0.5",
        f"--screenshot={shot}",
        page.as_uri(),
    )
    image = read_png(shot)
    assert image[:2] == (640, 1200)
    with_plots = count_color(image, ORANGE)
    # the same page without its SVG plots: the orange pixels were the bars
    bare = tmp_path / "bare.html"
    bare.write_text(re.sub(r"<svg .*?</svg>", "", page.read_text(), flags=re.S))
    shot2 = tmp_path / "bare.png"
    _run(
        chromium,
        tmp_path,
        "--hide-scrollbars",
        "--window-size=1280,2400",
        "--force-device-scale-factor=0.5",
        f"--screenshot={shot2}",
        bare.as_uri(),
    )
    without = count_color(read_png(shot2), ORANGE)
    assert with_plots >= 1500, with_plots
    assert without == 0


def test_script_errors_are_caught(chromium, page, tmp_path):
    broken = tmp_path / "broken.html"
    broken.write_text(page.read_text().replace("</main>", "</main><script>undefinedFunction();</script>"))
    body = _body(_run(chromium, tmp_path, "--dump-dom", broken.as_uri()).stdout)
    assert re.search(r'data-js-errors="[^"]*undefinedFunction[^"]*"', body)


def test_missing_browser_fails_unless_opted_out(monkeypatch):
    """The fixture's two answers when no browser is found: a failure naming the fix, or, with the
    opt-out variable, a skip naming the variable."""
    monkeypatch.setattr(shutil, "which", lambda name: None)
    monkeypatch.delenv(OPT_OUT, raising=False)
    with pytest.raises(
        pytest.fail.Exception,
        match=r"^no Chromium found \(looked for chromium, chromium-browser, google-chrome on PATH\).*RECAP_SKIP_BROWSER=1",
    ):
        browser_or_fail()
    monkeypatch.setenv(OPT_OUT, "1")
    with pytest.raises(pytest.skip.Exception, match=r"^RECAP_SKIP_BROWSER=1: "):
        browser_or_fail()
