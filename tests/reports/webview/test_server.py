"""``recap view`` over HTTP without a browser, on the known run of tests/doubles/known_run.py
(rows written with the schemas directly): bad requests are a 4xx with one line, never a
traceback; loopback and GET only; no secret served; the exact window of a call; the list's
paging, filters and search; new part files show up; the connection reaches no file."""

from __future__ import annotations

import http.client
import re
import urllib.request
from pathlib import Path

import duckdb
import pyarrow.parquet as pq
import pytest

from pipeline.cli.view import view_main
from reports.webview import data as D
from reports.webview.pages import observation_diff
from reports.webview.server import serve, stop
from schemas.tables import arrow_schema
from tests.doubles.known_run import write_run_a


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    folder = write_run_a(tmp_path_factory.mktemp("view") / "runA")
    # a sweep file with a key in it (the pipeline refuses such files; an old or hand-made run may hold one)
    t = pq.read_table(folder / "run")
    spec = "run: A\nmodels:\n  - model: gpt-4o\n    api_key: sk-live-abcdefghijklmnop1234\n    api_key_env: OPENAI_API_KEY\nrun_cap_usd: 40\n"
    rows = t.to_pylist()
    for r in rows:
        r["spec_yaml"] = spec
    for f in (folder / "run").glob("*.parquet"):
        f.unlink()
    pq.write_table(
        __import__("pyarrow").Table.from_pylist(rows, schema=arrow_schema("run")), folder / "run" / "part-t-000001.parquet"
    )
    return folder


@pytest.fixture(scope="module")
def viewer(run):
    server, thread = serve([run], 0, poll_s=0)
    yield server
    stop(server, thread)


def get(server, path: str, *, host: str | None = None, method: str = "GET") -> tuple[int, dict, str]:
    conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=30)
    headers = {"Host": host} if host else {}
    conn.request(method, path, headers=headers)
    r = conn.getresponse()
    body = r.read().decode("utf-8", errors="replace")
    conn.close()
    return r.status, dict(r.getheaders()), body


def error_line(body: str) -> str:
    m = re.search(r'<p class="error" id="error">(.*?)</p>', body, re.S)
    assert m, body[:300]
    return m.group(1)


@pytest.mark.parametrize(
    "path, status, message",
    [
        ("/nope", 404, "no page /nope"),
        ("/episodes?sort=password", 400, "cannot sort by &#x27;password&#x27;"),
        ("/episodes?page=0", 400, "page must be between 1 and 1000000"),
        ("/episodes?page=x", 400, "page and per must be whole numbers"),
        ("/episodes?per=7", 400, "per must be one of 25, 50, 100, 200"),
        ("/episodes?mode=nosuch", 400, "no episode has mode = &#x27;nosuch&#x27;"),
        ("/episodes?success=maybe", 400, "success must be true or false"),
        ("/episodes?debug=1", 400, "unknown parameter(s): debug"),
        ("/episodes?q=" + "x" * 201, 400, "search text longer than 200 characters"),
        ("/episode", 400, "missing parameter id"),
        ("/episode?id=nope", 404, "no episode &#x27;nope&#x27; in these runs"),
        ("/episode?id=A-recap-t2-42&run=other", 404, "no episode &#x27;A-recap-t2-42&#x27; in run &#x27;other&#x27;"),
        ("/window?id=A-recap-t2-42&call=-1", 400, "call must be a whole number &gt;= 0"),
        ("/window?id=A-recap-t2-42&call=999", 404, "episode &#x27;A-recap-t2-42&#x27; has no call 999"),
        ("/window?id=A-recap-t2-42&call=1&call=2", 400, "give call once"),
        ("/compare?kind=run&a=runA&b=runA", 400, "choose two different runs"),
        ("/compare?kind=model&a=x", 400, "compare what? kind must be run or arm"),
        ("/compare?kind=arm&a=nosuch&b=react", 400, "no arm named &#x27;nosuch&#x27;"),
        ("/spec?run=nosuch", 404, "no sweep file recorded for run &#x27;nosuch&#x27;"),
        ("/static/../data.py", 404, "no page /static/../data.py"),
    ],
)
def test_bad_requests_are_4xx_with_one_line(viewer, path, status, message):
    code, headers, body = get(viewer, path)
    assert (code, error_line(body)) == (status, message)
    assert "Traceback" not in body and headers["Content-Type"] == "text/html; charset=utf-8"


def test_loopback_get_only_and_headers(viewer):
    assert viewer.server_address[0] == "127.0.0.1"
    code, _, body = get(viewer, "/", host="evil.example:80")
    assert (code, error_line(body)) == (400, "this viewer answers only on its loopback address")
    for method in ("POST", "PUT", "DELETE"):
        code, headers, _ = get(viewer, "/", method=method)
        assert (code, headers["Allow"]) == (405, "GET, HEAD")
    code, headers, _ = get(viewer, "/")
    assert code == 200
    assert headers["X-Content-Type-Options"] == "nosniff"
    assert headers["Content-Security-Policy"].startswith("default-src 'none'; script-src 'self'; style-src 'self'")


def test_no_secret_is_served(viewer):
    code, _, body = get(viewer, "/spec?run=runA")
    assert code == 200
    assert "sk-live" not in body and "abcdefghijklmnop" not in body
    assert "api_key: &lt;redacted&gt;" in body and "api_key_env: OPENAI_API_KEY" in body
    _, _, runs = get(viewer, "/")
    assert "sk-live" not in runs and "run_cap_usd 40" in runs


def test_redact_spec():
    text = "models:\n  - model: m\n    api_key: abc\n    token: null\n    api_key_env: K\nnote: key sk-abcdefgh12345678 here\n"
    assert D.redact_spec(text) == (
        "models:\n  - model: m\n    api_key: <redacted>\n    token: null\n    api_key_env: K\nnote: key <redacted> here\n"
    )


def test_call_window_is_rebuilt_exactly(viewer):
    code, _, body = get(viewer, "/window?id=A-recap-t2-42&call=3&fragment=1")
    assert code == 200
    assert body.startswith(
        '<div class="window" data-run="runA" data-episode="A-recap-t2-42" data-call="3"><p class="window-head">Window of call 3 ('
    )
    assert re.findall(r'<li class="msg [^"]*" id="msg-(\d+)"', body) == ["0", "1", "6", "7"]
    assert "reply stored as message 8" in body
    assert "<pre>Done: prepare onion. Observation: You hold the onion.</pre>" in body


def test_list_paging_filters_and_search(viewer, run):
    snap = viewer.catalog.snap
    all_ids = sorted(r["episode_id"] for r in pq.read_table(run / "episodes").to_pylist())
    page = D.episode_list(snap, D.parse_list_query({"per": ["25"]}, snap))
    assert page.total == len(all_ids) and [r["episode_id"] for r in page.rows] == sorted(all_ids)[:25]
    ok = D.episode_list(snap, D.parse_list_query({"success": ["true"], "sort": ["cost_usd"], "dir": ["desc"]}, snap))
    costs = [r["cost_usd"] for r in ok.rows]
    assert all(r["success"] for r in ok.rows) and costs == sorted(costs, reverse=True) and ok.total == len(ok.rows) > 0
    msgs = pq.read_table(run / "messages").to_pylist()
    expected = sorted({m["episode_id"] for m in msgs if "you hold the onion" in m["content"].lower()})
    found = D.episode_list(snap, D.parse_list_query({"q": ["YOU HOLD  the Onion"]}, snap))
    assert sorted(r["episode_id"] for r in found.rows) == expected and expected
    # the second look at the same search reads the kept hits
    assert len(snap.hits) == 1
    D.episode_list(snap, D.parse_list_query({"q": ["you hold the onion"], "page": ["1"]}, snap))
    assert len(snap.hits) == 1


def test_new_part_files_show_up(tmp_path):
    folder = write_run_a(tmp_path / "live")
    catalog = D.Catalog([folder], poll_s=0)
    try:
        before = catalog.snap.query("SELECT count(*) AS n FROM _episode_list").rows[0][0]
        assert catalog.refresh() is False
        t = pq.read_table(sorted((folder / "episodes").glob("part-*.parquet"))[0]).slice(0, 1).to_pylist()
        t[0]["episode_id"], t[0]["unit_id"] = "LIVE-1", "live-unit"
        pq.write_table(
            __import__("pyarrow").Table.from_pylist(t, schema=arrow_schema("episodes")),
            folder / "episodes" / "part-live-000001.parquet",
        )
        assert catalog.refresh() is True
        snap = catalog.snap
        assert snap.query("SELECT count(*) FROM _episode_list").rows[0][0] == before + 1
        assert D.find_episode(snap, "LIVE-1", None) == ("runA", "LIVE-1")
    finally:
        catalog.close()


def test_the_connection_reaches_no_file(viewer, run):
    con = viewer.catalog.snap.con
    for sql in (
        f"SELECT * FROM read_parquet('{run}/episodes/*.parquet')",
        "SELECT * FROM read_csv('/etc/passwd')",
        f"COPY (SELECT 1) TO '{run}/x.csv'",
        "SET enable_external_access = true",
    ):
        with pytest.raises(duckdb.Error):
            con.execute(sql)
    assert not (run / "x.csv").exists()


def test_observation_diff():
    assert observation_diff(None, "a\nb") == "a\nb"
    assert observation_diff("a\nb\nc", "a\nB\nc\nd") == (
        '<span class="same">a</span>\n<del>b</del>\n<ins>B</ins>\n<span class="same">c</span>\n<ins>d</ins>'
    )


def test_view_command_errors(tmp_path, capsys):
    assert view_main([str(tmp_path / "missing")]) == 2
    assert capsys.readouterr().err == f"recap: error: view: run folder {tmp_path / 'missing'} does not exist or is not a folder\n"
    assert view_main(["--port", "70000", str(tmp_path)]) == 2
    assert capsys.readouterr().err == "recap: error: view: --port must be between 0 and 65535\n"


def test_pages_render(viewer):
    from urllib.parse import urlencode

    arms = viewer.catalog.snap.options["arm"]
    assert len(arms) >= 2
    for path in (
        "/",
        "/episodes",
        "/episode?id=A-recap-t2-42",
        "/compare",
        "/compare?" + urlencode({"kind": "arm", "a": arms[0], "b": arms[1]}),
        "/static/app.js",
        "/static/app.css",
        "/ping.gif",
    ):
        code, _, body = get(viewer, path)
        assert code == 200, (path, body[:300])
    with urllib.request.urlopen(viewer.url + "episode?id=A-recap-t2-42") as r:
        page = r.read().decode()
    assert 'data-episode="A-recap-t2-42"' in page and 'href="/window?run=runA&amp;id=A-recap-t2-42&amp;call=3"' in page


def test_compare_tests_swap_whole_instances(viewer):
    """react vs recap on run A: 7 paired units in 4 instances (gpt-4o: ALFWorld p1, sync i2 x 2 seeds, i6 x 3;
    the test double: ALFWorld p1). recap alone solved 5 units; per instance only-A minus only-B is -1, -1, -1, -2:
    |sum| 5 is reached only by the 2 one-sign patterns of 2^4 (pair by pair it was 2 of 2^5). Cost differences
    per instance: -0.5, 0.0 (dropped), -2.0, -6.25 -> 2 of 2^3."""
    from urllib.parse import urlencode

    code, _, body = get(viewer, "/compare?" + urlencode({"kind": "arm", "a": "react", "b": "recap"}))
    assert code == 200
    summary = re.search(r'<table class="data" id="summary">.*?<tbody>(.*?)</tbody>', body, re.S)
    assert summary
    cells = re.findall(r'<td class="num">(.*?)</td>', summary.group(1))
    assert cells[:6] == ["7", "1", "6", "0", "5", "0.1250"] and cells[7] == "0.2500"
    note = re.search(r'<p class="note" id="tests">(.*?)</p>', body, re.S)
    assert note and note.group(1).startswith(
        "McNemar p: clustered McNemar test, exact: the two arms swapped within each instance, all its seeds together"
    )
    assert note.group(1).endswith(
        "cost p: two-sided sign-flip permutation test over instances (each instance&#x27;s paired differences summed "
        "over its seeds, the sign flipped per instance): exact, all 2^3 patterns."
    )
