"""Runs are named, not shown by their hex ids (issue 36 item 8): the HTML report's tables and the viewer's
compare page show run.json's ``run`` (the id on hover / as the option's value). On the SWE run of
tests/doubles/swe_run.py (run id ``runS``, name ``swerun``)."""

from __future__ import annotations

import io
import re
import urllib.request

from pipeline.cli.report import report_main
from reports.webview.server import serve, stop
from tests.doubles.swe_run import RUN_ID, write_swe_run

NAME = "swerun"


def test_html_report_tables_name_the_run(tmp_path):
    folder = write_swe_run(tmp_path / "runS")
    assert report_main([str(folder), "--format", "html"], stdout=io.StringIO(), stderr=io.StringIO()) == 0
    html = (folder / "report" / "report.html").read_text()
    runs = re.search(r'<table class="data" data-source="runs\.sql">.*?</table>', html, re.S).group(0)
    assert f'<td class=""><span class="run" title="{RUN_ID}">{NAME}</span></td>' in runs
    assert not re.search(rf"<td[^>]*>{RUN_ID}</td>", html)  # no table cell shows the bare id


def test_compare_page_offers_runs_by_name(tmp_path):
    folder = write_swe_run(tmp_path / "runS")
    server, thread = serve([folder], 0, poll_s=0)
    try:
        with urllib.request.urlopen(server.url + "compare", timeout=30) as r:
            body = r.read().decode()
    finally:
        stop(server, thread)
    form = re.search(r'<form class="compare" id="compare-run".*?</form>', body, re.S).group(0)
    assert re.findall(r'<option value="([^"]*)"[^>]*>([^<]*)</option>', form) == [("", "choose"), (RUN_ID, NAME)] * 2
