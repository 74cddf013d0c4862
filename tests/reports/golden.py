"""The report's and the viewer's outputs over fixed inputs, for the golden test (tests/reports/test_golden.py).

The inputs are deterministic: the known runs of tests/doubles/known_run.py and a small synthetic run
(reports/synthetic.py, seed 0). The outputs: every file ``write_report`` writes (md, plots, html, tex,
csv) for each input, ``recap sql``'s text, CSV and JSON of a few queries, and the viewer's pages
(runs, spec, episode list with filters, search and sort, one episode, a call's window, compare), and the
synthetic run's part files (their SHA-256).
The folder the inputs were written to is replaced by ``<TMP>`` so the bytes do not depend on it.

    python -m tests.reports.golden OUT_DIR    (re)write the golden files (from the base commit cd47c8e)
"""

from __future__ import annotations

import hashlib
import http.client
import io
import re
import sys
import tempfile
from pathlib import Path
from typing import Any
from unittest import mock

import duckdb

from reports.build import ReportOptions, build_report, write_report
from reports.render_text import print_result
from reports.synthetic import SyntheticSpec, write_synthetic_run
from reports.views import open_runs_checked, run_query
from reports.webview.server import serve, stop
from tests.doubles.known_run import write_run_a, write_run_b

GOLDEN_DIR = Path(__file__).resolve().parent / "golden"
SYNTHETIC = SyntheticSpec(messages=6000, mean_calls=12, window=16, seed=0, part_rows=2000, row_group_rows=500)
#: the viewer's pages: the URL and the name its body is kept under
PAGES = (
    ("/", "runs"),
    ("/spec?run=runA", "spec"),
    ("/episodes", "episodes"),
    ("/episodes?sort=cost_usd&dir=desc&per=25", "episodes_sorted"),
    ("/episodes?q=onion&latest=1", "episodes_search"),
    ("/episodes?success=true&run=synthetic&page=2&per=25", "episodes_filtered"),
    ("/episodes?page=999", "episodes_past_end"),
    ("/episodes?nope=1", "episodes_bad"),
    ("/episode?id=ep-0000003", "episode_synthetic"),
    ("/window?id=ep-0000003&call=2", "window"),
    ("/window?id=ep-0000003&call=2&fragment=1", "window_fragment"),
    ("/compare", "compare_empty"),
    ("/compare?kind=run&a=runA&b=runB", "compare_runs"),
    ("/compare?kind=arm&a=recap%20ctx%2016&b=react%20ctx%2016", "compare_arms"),
    ("/compare?kind=arm&a=recap%20ctx%2064&b=react%20ctx%2064", "compare_arms_known"),
    ("/compare?kind=arm&a=act&b=act", "compare_same"),
    ("/compare?kind=arm&a=act&b=nope", "compare_unknown"),
)
QUERIES = (
    "SELECT arm, count(*) AS n, avg(cost_usd) AS cost FROM attempts GROUP BY ALL ORDER BY ALL",
    "SELECT run_id, episode_id, success, end_reason FROM attempts ORDER BY run_id, episode_id LIMIT 12",
)


def _episode_pages(run_dirs: list[Path]) -> list[tuple[str, str]]:
    """One episode page of each known run (their ids come from the rows, not from this file)."""
    con, _ = open_runs_checked(run_dirs)
    try:
        rows = run_query(con, "SELECT run_id, min(episode_id) AS e FROM attempts GROUP BY ALL ORDER BY ALL").rows
    finally:
        con.close()
    return [(f"/episode?id={e}&run={r}", f"episode_{r}") for r, e in rows]


def _viewer_pages(run_dirs: list[Path]) -> dict[str, bytes]:
    server, thread = serve(run_dirs, 0, poll_s=0)
    out: dict[str, bytes] = {}
    try:
        for path, name in PAGES + tuple(_episode_pages(run_dirs)):
            conn = http.client.HTTPConnection("127.0.0.1", server.server_address[1], timeout=60)
            conn.request("GET", path)
            r = conn.getresponse()
            body = r.read()
            conn.close()
            # how long the query took and when the snapshot was built: the parts that change between builds
            out[f"view/{name}.html"] = f"{r.status}\n".encode() + _no_timing(body)
    finally:
        stop(server, thread)
    return out


def _no_timing(body: bytes) -> bytes:
    body = re.sub(rb'data-ms="[0-9.]+"', b'data-ms="<N>"', body)
    return re.sub(rb"Data as of \d{4}-\d\d-\d\d \d\d:\d\d:\d\d", b"Data as of <TIME>", body)


def _sql_texts(run_dirs: list[Path]) -> dict[str, bytes]:
    con, _ = open_runs_checked(run_dirs)
    out: dict[str, bytes] = {}
    try:
        for i, sql in enumerate(QUERIES):
            res = run_query(con, sql)
            for fmt in ("table", "csv", "json"):
                buf = io.StringIO()
                print_result(res, fmt, 100, buf)
                out[f"sql/q{i}.{fmt}"] = buf.getvalue().encode()
    finally:
        con.close()
    return out


def _report_files(run_dirs: list[Path], out_dir: Path, options: ReportOptions) -> dict[str, bytes]:
    report = build_report(run_dirs, options)
    return {str(p.relative_to(out_dir)): p.read_bytes() for p in write_report(report, out_dir, options.formats)}


def _one_thread_connect(*args: Any, **kwargs: Any) -> duckdb.DuckDBPyConnection:
    """DuckDB with one thread: a parallel sum adds its floats in an order that changes from run to run (the last
    digit of a mean moves), and a golden file must not."""
    con = _CONNECT(*args, **kwargs)
    con.execute("SET threads = 1")
    return con


_CONNECT = duckdb.connect


def golden_outputs(base: Path) -> dict[str, bytes]:
    """Every output over the fixed inputs written under ``base``, by name, with ``base`` replaced by ``<TMP>``."""
    with mock.patch("duckdb.connect", _one_thread_connect):
        return _outputs(base)


def _outputs(base: Path) -> dict[str, bytes]:
    run_a = write_run_a(base / "runA")
    run_b = write_run_b(base / "runB")
    synth = base / "synthetic"
    write_synthetic_run(synth, SYNTHETIC)
    cases = {
        "a": ([run_a], ReportOptions()),
        "ab": ([run_a, run_b], ReportOptions()),
        "synthetic": ([synth], ReportOptions()),
        "synthetic_paper": ([synth], ReportOptions(formats=("md", "tex", "csv"), paper_only=True)),
        "all": ([run_a, run_b, synth], ReportOptions(formats=("md", "html"))),
    }
    out: dict[str, bytes] = {}
    for name, (dirs, options) in cases.items():
        for rel, data in _report_files(dirs, base / "out" / name, options).items():
            out[f"report/{name}/{rel}"] = data
    out.update(_sql_texts([run_a, run_b, synth]))
    out.update(_viewer_pages([run_a, run_b, synth]))
    # the synthetic run's part files by digest (a megabyte of Parquet is not worth keeping in the repository)
    out["synthetic/parquet.sha256"] = "".join(
        f"{hashlib.sha256(f.read_bytes()).hexdigest()}  {f.relative_to(synth)}\n" for f in sorted(synth.rglob("*.parquet"))
    ).encode()
    root = str(base).encode()
    return {k: v.replace(root, b"<TMP>") for k, v in sorted(out.items())}


def main(argv: list[str]) -> int:
    """Write the golden files under OUT_DIR (default tests/reports/golden)."""
    target = Path(argv[0]) if argv else GOLDEN_DIR
    with tempfile.TemporaryDirectory() as tmp:
        outputs = golden_outputs(Path(tmp))
    for rel, data in outputs.items():
        path = target / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    print(f"{len(outputs)} files, {sum(map(len, outputs.values())):,} bytes under {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
