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
    browser.eval(f"Array.from(document.querySelectorAll('a.ep')).find(a => a.dataset.episode === {json.dumps(eid)}).click()")
    browser.wait_ready(viewer.url + "episode?")
    assert browser.eval("document.getElementById('episode').dataset.episode") == eid
    shot_ok(browser, tmp_path / "episode.png")

    assert browser.eval("document.querySelectorAll('#tree details.node').length") == len(mine)
    closed = browser.eval("document.querySelectorAll('#tree details.node:not([open])').length")
    assert closed == sum(1 for n in mine.values() if n["depth"] > 0) and closed > 0
    browser.eval("document.getElementById('expand-all').click()")
    assert browser.eval("document.querySelectorAll('#tree details.node:not([open])').length") == 0
    # each node's latest version on show (a leaf that is its own action shows none), every version of a
    # refined node, with its subtasks, in order, in its folded timeline
    shown = browser.eval(
        "Object.fromEntries(Array.from(document.querySelectorAll('#tree details.node')).map(d => [d.dataset.node, "
        "[Array.from(d.querySelectorAll(':scope > ol.versions.latest > li')).map(v => "
        "Array.from(v.querySelectorAll('ol.subtasks > li')).map(li => li.textContent)), "
        "Array.from(d.querySelectorAll(':scope > details.history > ol.versions > li')).map(v => "
        "Array.from(v.querySelectorAll('ol.subtasks > li')).map(li => li.textContent))]]))"
    )

    def own_action(n: dict) -> bool:
        return (
            len(n["versions"]) == 1
            and n["versions"][0]["call_index"] is None
            and list(n["versions"][0]["subtasks"]) == [n["task"]]
        )

    assert shown == {
        str(k): [
            [] if own_action(n) else [list(n["versions"][-1]["subtasks"])],
            [list(v["subtasks"]) for v in n["versions"]] if len(n["versions"]) > 1 else [],
        ]
        for k, n in mine.items()
    }
    assert browser.eval("document.querySelectorAll('#tree details.history[open]').length") == 0

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


#: where the screenshots of issue 36's "Must show" are copied for the integrator (outside the repository), when set
SHOTS_ENV = "RECAP_VIEW_SHOTS"


def keep_shot(path: Path) -> None:
    """Copy a screenshot to the folder $RECAP_VIEW_SHOTS names (nothing when unset)."""
    import os

    if os.environ.get(SHOTS_ENV):
        dest = Path(os.environ[SHOTS_ENV])
        dest.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, dest / path.name)


@pytest.fixture(scope="module")
def wide_browser():
    b = Browser(CHROMIUM, width=1400, height=900)
    yield b
    b.close()


@pytest.fixture(scope="module")
def long_viewer(real_runs, long_run):
    server, thread = serve([*real_runs, long_run], 0, poll_s=0)
    yield server
    stop(server, thread)


OUTCOME = ("success", "end", "mode", "steps", "calls", "cost")


def test_episode_list_outcome_inside_1400px(long_viewer, wide_browser, real_runs, long_run, tmp_path):
    """Issue 36 item 8: at 1400 px the outcome columns (success, end, mode, steps, calls, cost) come first and
    every cell of them lies inside the viewport, with a 100-call Robotouille episode's long instance id in the
    list; runs are named, not hex ids, in the list and its run filter."""
    browser = wide_browser
    browser.goto(long_viewer.url + "episodes")
    heads = browser.eval(
        "Array.from(document.querySelectorAll('#episodes thead th')).map(t => t.textContent.replace(/ [▲▼]$/, ''))"
    )
    assert tuple(heads[: len(OUTCOME)]) == OUTCOME
    right = browser.eval(
        f"Math.max(...Array.from(document.querySelectorAll('#episodes tr')).map(r => "
        f"r.cells[{len(OUTCOME) - 1}].getBoundingClientRect().right))"
    )
    assert 0 < right <= 1400
    assert browser.eval("document.documentElement.scrollWidth") <= 1400  # nothing at all off-screen to the right
    names = {run_id(d): f"view-{d.name}" for d in (*real_runs, long_run)}
    runs_shown = browser.eval(
        "Array.from(document.querySelectorAll('#episodes tbody tr[data-episode]')).map(r => "
        "[r.dataset.run, r.cells[Array.from(document.querySelectorAll('#episodes thead th')).findIndex(t => t.textContent === 'run')].textContent])"
    )
    assert runs_shown and all(name == names[rid] for rid, name in runs_shown)
    options = browser.eval(
        "Array.from(document.querySelectorAll('select[name=run] option')).slice(1).map(o => [o.value, o.textContent])"
    )
    assert sorted(options) == sorted([rid, n] for rid, n in names.items())
    path = tmp_path / "episodes-1400px.png"
    browser.eval("window.scrollTo(0, 0)")
    img = read_png(browser.screenshot(path))
    assert img[:2] == (1400, 900)
    keep_shot(path)
    no_errors(browser)


def test_long_recap_episode_one_screen_per_subtree(long_viewer, wide_browser, long_run, tmp_path):
    """Issue 36 item 9: a ReCAP episode of about 100 calls; each node shows its latest version and its children,
    its older versions folded into its timeline, so that every subtree under the root, opened whole, fits one
    900 px screen; the root's timeline lists every version in call order."""
    browser = wide_browser
    (ep,) = table([long_run], "episodes")
    assert ep["method"] == "recap" and ep["llm_calls"] >= 90
    nodes = {n["node_id"]: n for n in table([long_run], "tree_nodes")}
    root = next(n for n in nodes.values() if n["parent_id"] is None)
    assert len(root["versions"]) > 1
    browser.goto(long_viewer.url + f"episode?run={run_id(long_run)}&id={ep['episode_id']}")
    browser.eval("document.getElementById('expand-all').click()")
    heights = browser.eval(
        "Array.from(document.querySelectorAll('#tree ul.root > li > details.node > ul.tree > li > details.node'))"
        ".map(d => [d.dataset.node, d.getBoundingClientRect().height])"
    )
    assert sorted(int(k) for k, _ in heights) == sorted(k for k, n in nodes.items() if n["parent_id"] == root["node_id"])
    assert all(0 < h <= 900 for _, h in heights), heights
    # the root: its latest version, then its first child straight after (one version, not every one)
    latest = browser.eval(
        "Array.from(document.querySelectorAll('#tree ul.root > li > details.node > ol.versions.latest > li')).map(v => v.dataset.version)"
    )
    assert latest == [str(root["versions"][-1]["version"])]
    timeline = browser.eval(
        "Array.from(document.querySelectorAll('#tree ul.root > li > details.node > details.history > ol.versions > li'))"
        ".map(v => v.querySelector('.tag').textContent)"
    )
    purpose = {c["call_index"]: c["purpose"] for c in table([long_run], "llm_calls")}
    assert timeline == [
        (f"call {v['call_index']} ({purpose[v['call_index']]})" if v["call_index"] is not None else "shortcut")
        + f" → v{v['version']}"
        for v in root["versions"]
    ]
    first_child = browser.eval(
        "document.querySelector('#tree ul.root > li > details.node > ul.tree > li').getBoundingClientRect().top"
    )
    tree_top = browser.eval("document.getElementById('tree').getBoundingClientRect().top")
    assert first_child - tree_top < 300  # the root's 5+ versions no longer stand between it and its first child
    browser.eval("document.getElementById('tree').scrollIntoView()")
    path = tmp_path / "recap-100-calls-1400px.png"
    img = read_png(browser.screenshot(path))
    assert img[:2] == (1400, 900)
    keep_shot(path)
    no_errors(browser)
