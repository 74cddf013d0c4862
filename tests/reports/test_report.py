"""`recap report` and `recap sql` end to end over the known run: files, exact lines, labels, errors."""

from __future__ import annotations

import csv
import io
import json
import re
import shutil

import pytest

from pipeline.cli.report import report_main
from pipeline.cli.sql import sql_main
from reports.render_text import format_table
from reports.viewer import MAX_MESSAGE_CHARS, _cut, ranges
from reports.views import Result
from schemas.parts import part_files


def _run(main, argv):
    out, err = io.StringIO(), io.StringIO()
    rc = main(argv, stdout=out, stderr=err)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def report_dir(run_a, tmp_path_factory):
    out = tmp_path_factory.mktemp("report")
    rc, stdout, stderr = _run(report_main, [str(run_a), "--out", str(out)])
    assert (rc, stderr) == (0, "")
    assert stdout.startswith(f"wrote 64 files to {out} (md, html, tex, csv)\n")  # 13 of the paper section
    return out


def test_report_files(report_dir):
    names = sorted(str(p.relative_to(report_dir)) for p in report_dir.rglob("*") if p.is_file())
    assert "report.md" in names and "report.html" in names and "tex/report.tex" in names
    assert sorted(n for n in names if n.startswith("plots/")) == [
        "plots/context_by_call.svg",
        "plots/cost_per_episode.svg",
        "plots/failure_modes.svg",
        "plots/success_by_split.svg",
        "plots/tree_branching_factor.svg",
        "plots/tree_leaf_failures.svg",
        "plots/tree_levels.svg",
    ]
    assert len([n for n in names if n.startswith("csv/")]) == 32  # + paper_cells/pairs/trees, 5 paper_table_*
    assert len([n for n in names if n.startswith("tex/")]) == 23  # 17 tables + 5 paper tables + report.tex
    assert not [n for n in names if ".tmp-" in n]


def test_markdown_main_table(report_dir):
    md = (report_dir / "report.md").read_text()
    table = md[md.index("### Success rate by method and environment split") :].split("\n\n")[2]
    assert table.splitlines() == [
        "| model | method | alfworld/valid_unseen | robotouille/synchronous |",
        "|---|---|---:|---:|",
        "| gpt-4o | react | 0.0 [0.0, 79.3] 0/1 | 20.0 [2.9, 68.0] 1/5 |",
        "| gpt-4o | recap | 100.0 [20.7, 100.0] 1/1 | 80.0 [37.6, 96.4] 4/5 |",
        "| gpt-4o | recap[level_3] | – | 50.0 [9.5, 90.5] 1/2 |",
        "| scripted (test double) | react | 0.0 [0.0, 79.3] 0/1 | – |",
        "| scripted (test double) | recap | 50.0 [9.5, 90.5] 1/2 | – |",
    ]
    # paper numbers appear only in the paper section, behind the protocol check (the fixture's arms
    # ran no profile, so every paper cell there is a footnote mark)
    success = md[md.index("## Success rates") : md.index("## Costs")]
    assert "paper |" not in success and "84.0" not in success and "91.0" not in success
    assert "[1] profile none, the paper's runs are profile paper." in md[md.index("## The paper's tables") :]
    assert (
        # McNemar and cost p swap the arms per instance (i2: 2 seeds, i6: 3): 2 of 4 sign patterns each
        "| gpt-4o | robotouille/synchronous | react | recap | 5 | 20.0 | 80.0 | 0 | 3 | 0.5000 | 1.0000 | -$1.6500 | 0.5000 | 1.0000 |"
        in md
    )
    assert (
        "| gpt-4o | recap | robotouille/synchronous | 64 | level_3 | 50.0 [9.5, 90.5] 1/2 | 2 | 1 | 0 | 1.0000 | 1.0000 |" in md
    )
    assert (
        "| gpt-4o | recap | robotouille/synchronous | 2 | 3.50 | 2.50 | 0.71 | 1.75 | 0.35 | 3 | 5.50 | 0.50 | 1 | 1.00 |" in md
    )
    assert "| gpt-4o | invalid_action_loop | 1 | 7.1 | $1.0000 | 1.00 | 4.00 | A-react-t6-42 |" in md
    assert (
        "![Success rate by environment split (95% Wilson intervals, widened by the design effect where an instance ran "
        "several seeds)](plots/success_by_split.svg)" in md
    )


def test_test_doubles_are_labelled_everywhere(report_dir):
    """The test-double model 'scripted' never appears without its label, in any format."""
    unlabelled = re.compile(r"scripted(?! \(test double\))")
    for path in [
        report_dir / "report.md",
        report_dir / "report.html",
        *sorted((report_dir / "tex").glob("*.tex")),
        *sorted((report_dir / "csv").glob("*.csv")),
    ]:
        text = re.sub(r"</tspan><tspan[^>]*>", " ", path.read_text())  # SVG labels broken over lines
        if path.parent.name == "csv" and path.stem.startswith("viewer_"):
            continue  # raw rows of the viewer's episodes (model column is the model as called)
        assert not unlabelled.search(text), f"unlabelled test double in {path.name}"
    md = (report_dir / "report.md").read_text()
    tables_with_models = [t for t in md.split("### ")[1:] if "| model |" in t]
    assert len(tables_with_models) == 15  # 12 + the paper section's main, ALFWorld cost and cost-ratio tables
    assert (
        sum("scripted (test double)" in t for t in tables_with_models) == 13
    )  # all but the tree table (no tree) and the cost ratio (gpt-4o only)
    # the per-task table of ALFWorld names models in its column headers
    assert "| task | react · gpt-4o | recap · gpt-4o | react · scripted (test double) | recap · scripted (test double) |" in md


def test_csv_is_the_long_sql_result(report_dir):
    rows = list(csv.reader((report_dir / "csv" / "success_by_split.csv").open()))
    assert rows[0] == [
        "model_label",
        "arm",
        "env_split",
        "method",
        "ablation",
        "episodes",
        "successes",
        "success_rate",
        "ci_low",
        "ci_high",
        "instances",
        "deff",
    ]
    assert rows[6][:8] == ["gpt-4o", "recap", "robotouille/synchronous", "recap", "original", "5", "4", "0.8"]
    modes = list(csv.DictReader((report_dir / "csv" / "failure_modes.csv").open()))
    assert json.loads(modes[0]["examples"]) == ["A-lvl3-t6-126", "A-react-t2-42", "A-recap-alf-p1"]


def test_latex_tables(report_dir):
    main = (report_dir / "tex" / "main.tex").read_text()
    assert "model & method & alfworld/valid\\_unseen & robotouille/synchronous \\\\" in main
    assert "gpt-4o & recap[level\\_3] & -- & 50.0 [9.5, 90.5] 1/2 \\\\" in main
    assert main.count("\\toprule") == 1 and main.count("\\bottomrule") == 1
    doc = (report_dir / "tex" / "report.tex").read_text()
    assert doc.startswith("\\documentclass{article}") and doc.rstrip().endswith("\\end{document}")
    assert "\\input{main}" in doc and "\\input{paired}" in doc
    paired = (report_dir / "tex" / "paired.tex").read_text()
    assert "-\\$1.6500" in paired and "McNemar p" in paired


def test_html_is_self_contained(report_dir):
    html = (report_dir / "report.html").read_text()
    assert html.count("<svg ") == 7
    assert not re.search(r"""(src|href)=["'](https?:)?//""", html)
    assert "<link " not in html and "@import" not in html
    assert html.count('<article class="episode"') == 8
    # failure-mode examples link to their episode when (and only when) the viewer shows it
    shown = set(re.findall(r'<article class="episode" id="[^"]+" data-episode="([^"]+)"', html))
    linked = set(re.findall(r'<a href="#ep-([^"]+)">', html))
    assert linked == shown & {
        "A-lvl3-t6-126",
        "A-react-t2-42",
        "A-recap-alf-p1",
        "A-recap-t6-84",
        "A-react-t6-126",
        "A-react-t6-42",
        "A-react-alf-p1",
        "A-react-t6-84",
        "A-react-t2-84-a2",
        "A-lvl3-t6-42",
        "A-recap-alf-p2-td",
        "A-react-alf-p1-td",
        "A-recap-alf-p1-td",
    }
    assert len(linked) >= 6


def test_viewer_shows_tree_steps_calls_and_windows(run_a, tmp_path):
    rc, _, err = _run(report_main, [str(run_a), "--out", str(tmp_path), "--format", "html", "--episodes", "A-recap-t2-42"])
    assert (rc, err) == (0, "")
    html = (tmp_path / "report.html").read_text()
    assert html.count('<article class="episode"') == 1
    viewer = html[html.index('<section id="viewer"') :]
    # every version of the root, with its think and subtasks
    assert (
        '<span class="vtag">v0 · call 0</span><div class="think">plan it</div><ol class="subtasks"><li>prepare onion</li><li>serve</li><li>clean</li></ol>'
        in viewer
    )
    assert '<span class="vtag">v1 · call 3</span><div class="think">onion done</div>' in viewer
    assert '<li class="node failed"><span class="ntitle">#6 place onion on table9</span>' in viewer
    assert "<td>place onion on table9</td><td>no</td>" in viewer  # the rejected step
    assert (
        'id="call-ep-A-recap-t2-42-2" data-target="ep-A-recap-t2-42" data-seqs="0-5" data-response="6">6 msgs: 0-5</button>'
        in viewer
    )
    assert 'data-seqs="0-1,6-7" data-response="8">4 msgs: 0-1,6-7</button>' in viewer
    assert viewer.count('<li class="msg ') == 9
    assert not (tmp_path / "report.md").exists()


def test_viewer_sample_covers_methods_then_modes(run_a, tmp_path):
    rc, _, _ = _run(report_main, [str(run_a), "--out", str(tmp_path), "--format", "html", "--viewer-max", "5"])
    html = (tmp_path / "report.html").read_text()
    shown = re.findall(r'<article class="episode" id="[^"]+" data-episode="([^"]+)"', html)
    # turn 1: each (model, method)'s success, else its first mode; ordered by model, method
    assert shown == ["A-react-t2-42", "A-recap-alf-p1", "A-lvl3-t6-126", "A-react-alf-p1-td", "A-recap-alf-p1-td"]
    rc, _, _ = _run(report_main, [str(run_a), "--out", str(tmp_path), "--format", "html", "--viewer-max", "0"])
    assert '<section id="viewer"' not in (tmp_path / "report.html").read_text()


def test_viewer_cuts_long_texts():
    assert _cut("x" * (MAX_MESSAGE_CHARS + 5), MAX_MESSAGE_CHARS) == "x" * MAX_MESSAGE_CHARS + "\n… (5 more characters)"
    assert ranges([5, 0, 1, 2, 7, 8, 10]) == "0-2,5,7-8,10"
    assert ranges([]) == ""


def test_report_errors(run_a, run_b, tmp_path):
    assert _run(report_main, [str(run_a), "--out", str(tmp_path), "--episodes", "nope,A-recap-t2-42"])[::2] == (
        1,
        "recap: error: report: unknown episode id(s) for the viewer: nope\n",
    )
    assert _run(report_main, [str(run_a), "--out", str(tmp_path), "--format", "md,pdf"])[::2] == (
        1,
        "recap: error: report: unknown report format(s) pdf; choose from md, html, tex, csv\n",
    )
    assert _run(report_main, [str(run_a), str(run_b)])[::2] == (
        1,
        "recap: error: report: --out is required when reporting several run folders\n",
    )
    assert _run(report_main, [str(tmp_path / "missing")])[::2] == (
        2,
        f"recap: error: report: run folder {tmp_path / 'missing'} does not exist or is not a folder\n",
    )
    rc, _, err = _run(report_main, ["--format"])
    assert rc == 2 and err.startswith("recap: error: report: ")


def test_report_over_a_run_with_a_corrupt_part(run_a, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(run_a, run)
    bad = part_files(run, "llm_calls")[0]
    bad.write_bytes(bad.read_bytes()[:100])
    rc, out, err = _run(report_main, [str(run)])
    assert rc == 0
    assert err.startswith(f"warning: skipped unreadable part file {bad} (llm_calls): ")
    assert out.startswith(f"wrote 65 files to {run / 'report'} ")  # + the skipped-parts LaTeX table
    html = (run / "report" / "report.html").read_text()
    assert "<strong>Unreadable part files were skipped:</strong>" in html and str(bad) in html
    md = (run / "report" / "report.md").read_text()
    assert "| unreadable part files skipped | 1 |" in md
    assert "| LLM calls (all attempts) | 8 |" in md  # the other part file's 8 calls


# -- recap sql -------------------------------------------------------------------------------


def test_sql_prints_a_table(run_a):
    rc, out, err = _run(
        sql_main,
        [
            str(run_a),
            "SELECT mode, count(*) AS n, sum(cost_usd) AS usd FROM failures WHERE mode LIKE '%loop%' GROUP BY mode ORDER BY mode",
        ],
    )
    assert (rc, err) == (0, "")
    assert out == (
        "mode                 | n | usd\n"
        "---------------------+---+----\n"
        "invalid_action_loop  | 1 |   1\n"
        "repeated_action_loop | 1 | 0.5\n"
        "(2 rows)\n"
    )


def test_sql_csv_json_and_named_queries(run_a, run_b):
    rc, out, _ = _run(
        sql_main,
        [
            str(run_a),
            "SELECT episode_id, cost_usd, examples FROM (SELECT 'e' AS episode_id, 0.5 AS cost_usd, ['a', 'b'] AS examples)",
            "--csv",
        ],
    )
    assert (rc, out) == (0, 'episode_id,cost_usd,examples\ne,0.5,"[""a"", ""b""]"\n')
    rc, out, _ = _run(
        sql_main, [str(run_a), str(run_b), "SELECT run_id, count(*) AS n FROM terminal GROUP BY run_id ORDER BY run_id", "--json"]
    )
    # a unit is (run, unit id): run B re-running one of run A's unit ids takes none of run A's 18 units
    assert (rc, json.loads(out)) == (0, [{"run_id": "runA", "n": 18}, {"run_id": "runB", "n": 2}])
    rc, out, _ = _run(sql_main, [str(run_a), "@overview", "--json"])
    assert json.loads(out)[0]["units"] == 18


def test_sql_file_and_row_limit(run_a, tmp_path):
    q = tmp_path / "q.sql"
    q.write_text("SELECT seq FROM messages ORDER BY seq")
    rc, out, _ = _run(sql_main, [str(run_a), "--file", str(q), "--max-rows", "2"])
    assert (rc, out) == (0, "seq\n---\n  0\n  1\n(9 rows; 7 not shown, use --max-rows, --csv or --json)\n")


def test_sql_refuses_writes_and_bad_input(run_a, tmp_path):
    # every recap sql error: one line on stderr, exit status 2 (as every other recap command)
    rc, out, err = _run(sql_main, [str(run_a), "DROP VIEW episodes"])
    assert (rc, out, err) == (
        2,
        "",
        "recap: error: sql: refused DROP statement: reports are read-only (allowed: SELECT, WITH, DESCRIBE, SHOW, SUMMARIZE, EXPLAIN, read-only PRAGMA)\n",
    )
    rc, _, err = _run(sql_main, [str(run_a), "SELECT * FROM nosuchtable"])
    assert rc == 2 and err.startswith(
        "recap: error: sql: query failed: Catalog Error: Table with name nosuchtable does not exist!"
    )
    assert len(err.splitlines()) == 1
    assert _run(sql_main, [str(run_a)])[::2] == (2, "recap: error: sql: give at least one RUN_DIR and a QUERY\n")
    assert _run(sql_main, [str(run_a), "@nosuch"])[0] == 2
    assert _run(sql_main, [str(run_a), "--file", str(tmp_path / "none.sql")])[2].startswith(
        "recap: error: sql: cannot read query file"
    )
    assert _run(sql_main, [str(run_a), "SELECT 1", "--csv", "--json"])[0] == 2


def test_format_table_cuts_wide_cells():
    r = Result(["a", "b"], [("x" * 70, None), ("y", 1.23456789)])
    assert format_table(r).splitlines() == [
        "a" + " " * 59 + " |       b",
        "-" * 60 + "-+-" + "-" * 7,
        "x" * 59 + "… |    NULL",
        "y" + " " * 59 + " | 1.23457",
        "(2 rows)",
    ]


def test_html_report_opens_with_the_papers_tables_and_success_rates(report_dir):
    """Issue 36 item 12: the HTML page opens with the paper's tables and the success rates; the overview (what
    the report covers, the runs) comes after them, folded; the markdown keeps the report's order."""
    html = (report_dir / "report.html").read_text()
    order = re.findall(r'<section id="s-([a-z]+)">', html)
    assert order[:3] == ["paper", "success", "overview"]
    assert re.findall(r'<li><a href="#s-([a-z]+)">', html)[: len(order)] == order  # the contents list, in page order
    assert re.search(r'<section id="s-overview"><details class="folded"><summary><h2>Overview</h2></summary>', html)
    assert '<section id="s-paper"><h2>' in html and '<section id="s-success"><h2>' in html  # not folded
    md = (report_dir / "report.md").read_text()
    assert md.index("## Overview") < md.index("## Success rates") < md.index("## The paper's tables")
