"""``recap view`` in the distribution's headless Chromium, driven over the DevTools protocol
(tests/reports/webview/cdp.py), on two real runs (tests/reports/webview/conftest.py): the runs page, the episode list
with a filter and a search, an episode with its tree expanded and a call's exact window, the
comparison of the two runs with its discordant episodes, and a screenshot of every page. Every
expected value is read straight from the part files, not through the viewer's code. Skipped only
when no Chromium is installed (``apt-get install -y chromium``)."""

from __future__ import annotations

import json
import shutil
from collections import Counter
from fractions import Fraction
from pathlib import Path

import pytest

from reports.stats import clustered_mcnemar_exact, instance_discordance
from reports.webview.server import serve, stop
from tests.reports.png import count_color, read_png
from tests.reports.webview.cdp import Browser
from tests.reports.webview.conftest import table

CHROMIUM = next((p for p in (shutil.which(n) for n in ("chromium", "chromium-browser")) if p), None)
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="Chromium is not installed (apt-get install -y chromium)")

HEADER_BLUE = (0x4E, 0x79, 0xA7)


@pytest.fixture(scope="module")
def viewer(real_runs):
    server, thread = serve(list(real_runs), 0, poll_s=0)
    yield server
    stop(server, thread)


@pytest.fixture(scope="module")
def browser():
    b = Browser(CHROMIUM)
    yield b
    b.close()


def run_id(folder: Path) -> str:
    return json.loads((folder / "run.json").read_text())["run_id"]


def no_errors(b: Browser) -> None:
    assert b.eval("document.body.getAttribute('data-js-errors')") is None


def shot_ok(b: Browser, path: Path) -> None:
    """A screenshot of the top of the page: the viewport's size, the header bar painted, text on it."""
    b.eval("window.scrollTo(0, 0)")
    img = read_png(b.screenshot(path))
    assert img[:2] == (1280, 900)
    assert count_color(img, HEADER_BLUE) >= 1280 * 25  # the header bar (about 37 px high)
    assert count_color(img, (0x22, 0x22, 0x22), tol=40) >= 500  # dark text in the body
    assert len(set(img[3][i : i + 3] for i in range(0, 1280 * 900 * img[2], img[2] * 97))) > 4  # not one flat colour


def ids_on_page(b: Browser) -> list[str]:
    return b.eval("Array.from(document.querySelectorAll('#episodes tbody tr[data-episode]')).map(r => r.dataset.episode)")


def test_runs_page(viewer, browser, real_runs, tmp_path):
    browser.goto(viewer.url)
    rows = browser.eval(
        "Array.from(document.querySelectorAll('#runs tbody tr')).map(r => "
        "[r.dataset.run, r.cells[0].textContent, r.cells[5].textContent, r.cells[6].textContent])"
    )
    planned = {run_id(d): len(json.loads((d / "plan.json").read_text())["units"]) for d in real_runs}
    assert sorted(rows) == sorted(
        [[run_id(d), f"view-{d.name}", str(planned[run_id(d)]), str(planned[run_id(d)])] for d in real_runs]
    )
    no_errors(browser)
    shot_ok(browser, tmp_path / "runs.png")


def test_list_filter_and_search(viewer, browser, real_runs, tmp_path):
    episodes = table(real_runs, "episodes")
    browser.goto(viewer.url + "episodes")
    assert sorted(ids_on_page(browser)) == sorted(e["episode_id"] for e in episodes)
    assert browser.eval("document.getElementById('count').dataset.total") == str(len(episodes))
    shot_ok(browser, tmp_path / "episodes.png")

    # a filter: choosing a method reloads the list with that method's episodes only
    browser.eval("var s = document.querySelector('select[name=method]'); s.value = 'react'; s.dispatchEvent(new Event('change'))")
    browser.wait_ready(viewer.url + "episodes?method=react")
    assert sorted(ids_on_page(browser)) == sorted(e["episode_id"] for e in episodes if e["method"] == "react")

    # search: a line of one instance's task message, typed in another letter case; every
    # episode with a message that holds it (in any letter case), in any method
    messages = table(real_runs, "messages")
    task_lines = Counter(
        line for m in messages if m["kind"] == "task" for line in set(m["content"].splitlines()) if len(line) > 12
    )
    phrase = sorted(line for line, n in task_lines.items() if 0 < n < len(episodes) // 2)[0]
    expected = sorted({m["episode_id"] for m in messages if phrase.lower() in m["content"].lower()})
    assert 0 < len(expected) < len(episodes)
    browser.goto(viewer.url + "episodes")
    browser.eval(
        f"document.getElementById('q').value = {json.dumps(phrase.swapcase())}; "
        "document.getElementById('filters').requestSubmit()"
    )
    browser.wait_ready(viewer.url + "episodes?")
    assert sorted(ids_on_page(browser)) == expected
    no_errors(browser)


def test_episode_tree_and_call_window(viewer, browser, real_runs, tmp_path):
    nodes = table(real_runs, "tree_nodes")
    counts = Counter(n["episode_id"] for n in nodes)
    eid = max(sorted(counts), key=lambda e: counts[e])  # the recap episode with the largest tree
    mine = {n["node_id"]: n for n in nodes if n["episode_id"] == eid}
    # open it from the list, as a user would
    browser.goto(viewer.url + "episodes?method=recap")
    browser.eval(f"Array.from(document.querySelectorAll('a.ep')).find(a => a.textContent === {json.dumps(eid)}).click()")
    browser.wait_ready(viewer.url + "episode?")
    assert browser.eval("document.getElementById('episode').dataset.episode") == eid
    shot_ok(browser, tmp_path / "episode.png")

    assert browser.eval("document.querySelectorAll('#tree details.node').length") == len(mine)
    closed = browser.eval("document.querySelectorAll('#tree details.node:not([open])').length")
    assert closed == sum(1 for n in mine.values() if n["depth"] > 0) and closed > 0
    browser.eval("document.getElementById('expand-all').click()")
    assert browser.eval("document.querySelectorAll('#tree details.node:not([open])').length") == 0
    # every version of every node, with its subtasks, in order
    shown = browser.eval(
        "Object.fromEntries(Array.from(document.querySelectorAll('#tree details.node')).map(d => [d.dataset.node, "
        "Array.from(d.querySelector(':scope > ol.versions').children).map(v => "
        "Array.from(v.querySelectorAll('ol.subtasks > li')).map(li => li.textContent))]))"
    )
    assert shown == {str(k): [list(v["subtasks"]) for v in n["versions"]] for k, n in mine.items()}

    # the call with the longest window: its exact messages, in window order
    calls = [c for c in table(real_runs, "llm_calls") if c["episode_id"] == eid]
    call = max(calls, key=lambda c: (len(c["window_seqs"]), c["call_index"]))
    content = {m["seq"]: m["content"] for m in table(real_runs, "messages") if m["episode_id"] == eid}
    browser.eval(f"document.querySelector('a.window[data-call=\"{call['call_index']}\"]').click()")
    browser.wait_for(f"document.getElementById('window-panel').getAttribute('data-call') === '{call['call_index']}'")
    got = browser.eval(
        "Array.from(document.querySelectorAll('#window-panel li.msg')).map(li => [Number(li.dataset.seq), "
        "li.querySelector('pre').textContent])"
    )
    assert got == [[s, content[s]] for s in call["window_seqs"]]
    assert len(got) >= 3
    no_errors(browser)


def test_compare_two_runs(viewer, browser, real_runs, tmp_path):
    a_dir, b_dir = real_runs
    a, b = run_id(a_dir), run_id(b_dir)
    eps = table(real_runs, "episodes")
    latest: dict[tuple, dict] = {}
    for e in sorted(eps, key=lambda e: e["attempt"]):
        latest[(e["run_id"], e["method"], e["instance_id"], e["sampling_seed"])] = e
    pairs = [(latest[k], latest[(b, *k[1:])]) for k in sorted(latest) if k[0] == a and (b, *k[1:]) in latest]
    a_only = sum(1 for x, y in pairs if x["success"] and not y["success"])
    b_only = sum(1 for x, y in pairs if y["success"] and not x["success"])
    assert len(pairs) == 8 and a_only > 0

    browser.goto(viewer.url + "compare")
    browser.eval(
        f"var f = document.getElementById('compare-run'); f.elements.a.value = {json.dumps(a)}; "
        f"f.elements.b.value = {json.dumps(b)}; f.requestSubmit()"
    )
    browser.wait_ready(viewer.url + "compare?")
    summary = browser.eval("Array.from(document.querySelectorAll('#summary tbody td')).map(td => td.textContent)")
    # the arms are swapped per instance (all its seeds together): the clustered McNemar test
    p = clustered_mcnemar_exact(
        instance_discordance(
            [x["success"] for x, _ in pairs],
            [y["success"] for _, y in pairs],
            [(x["method"], x["instance_id"]) for x, _ in pairs],
        )
    )
    assert summary[:6] == [
        str(len(pairs)),
        str(sum(x["success"] for x, _ in pairs)),
        str(sum(y["success"] for _, y in pairs)),
        str(a_only),
        str(b_only),
        "<0.0001" if p < Fraction(1, 10000) else f"{float(p):.4f}",
    ]
    links = browser.eval(
        "Array.from(document.querySelectorAll('#discordant tbody tr')).map(r => "
        "Array.from(r.querySelectorAll('a.ep')).map(a => a.textContent))"
    )
    assert sorted(links) == sorted([x["episode_id"], y["episode_id"]] for x, y in pairs if x["success"] != y["success"])
    shot_ok(browser, tmp_path / "compare.png")
    # a discordant pair's B episode opens
    browser.eval("document.querySelectorAll('#discordant a.ep')[1].click()")
    browser.wait_ready(viewer.url + "episode?")
    assert browser.eval("document.getElementById('episode').dataset.episode") == links[0][1]
    no_errors(browser)


def test_report_episode_ids_link_to_the_viewer(viewer, browser, real_runs, tmp_path):
    import io

    from pipeline.cli.report import report_main

    a_dir = real_runs[0]
    assert report_main([str(a_dir), "--format", "html", "--viewer-max", "2"], stdout=io.StringIO(), stderr=io.StringIO()) == 0
    page = (a_dir / "report" / "report.html").as_uri()
    ids = sorted({e["episode_id"] for e in table([a_dir], "episodes")})
    # no viewer on that port: the static report keeps its own links
    browser.goto(page + "?viewer=1", "data-report-ready")
    browser.wait_for("document.body.getAttribute('data-viewer') === 'none'")
    assert browser.eval("document.querySelectorAll('.ep-link a[href^=\"http\"]').length") == 0
    # the viewer running: every episode id becomes a link to its page there
    port = viewer.server_address[1]
    browser.goto(page + f"?viewer={port}", "data-report-ready")
    browser.wait_for(f"document.body.getAttribute('data-viewer') === 'http://127.0.0.1:{port}/'")
    links = browser.eval(
        "Array.from(document.querySelectorAll('.ep-link')).map(el => [el.dataset.episode, el.querySelector('a').href])"
    )
    assert links and all(eid in ids and href.startswith(f"http://127.0.0.1:{port}/episode?id={eid}") for eid, href in links)
    browser.eval("document.querySelector('.ep-link a').click()")
    browser.wait_ready(viewer.url + "episode?")
    assert browser.eval("document.getElementById('episode').dataset.episode") == links[0][0]
    # served by the viewer itself (Runs page -> report): the links use its origin
    browser.goto(viewer.url + "report?run=" + run_id(a_dir), "data-report-ready")
    browser.wait_for(f"document.body.getAttribute('data-viewer') === '{viewer.url}'")
    no_errors(browser)
