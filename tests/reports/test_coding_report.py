"""``recap report`` over coding runs (issue 29): the paper's SWE-bench Verified row beside ours only under its
protocol, the coding section (outcomes by evaluation reason, our grading against the official harness, the
paper's two SWE-bench figures) in every format, and nothing of it for a run without coding episodes."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from pipeline.cli import main as recap_main
from reports import paper
from reports.build import FORMATS, ReportOptions, build_report, write_report
from tests.doubles.swe_run import write_swe_run
from tests.reports.conftest import assert_rows

SUBSET = "ran 4 of the paper's 500 instances (a subset)"


@pytest.fixture(scope="module")
def swe_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_swe_run(tmp_path_factory.mktemp("swe") / "runS")


@pytest.fixture(scope="module")
def full_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_swe_run(tmp_path_factory.mktemp("swefull") / "runS", full=True)


@pytest.fixture(scope="module")
def report(swe_run):
    return build_report([swe_run], ReportOptions(formats=("md", "csv")))


def _table(report, name):
    return next(t for s in report.sections for t in s.tables if t.name == name)


def _plot(report, name):
    return next(p for s in report.sections for p in s.plots if p.name == name)


def test_the_main_table_has_the_swe_verified_row_with_footnotes_for_a_subset(report):
    main = report.results["paper_table_main"]
    assert main.columns[:2] == ["benchmark", "model"]
    # mini_swe stands in ReAct's place (after ReCAP; ties by label)
    assert [c for c in main.columns if ":" not in c][2:] == ["recap", "mini_swe", "react"]
    assert main.rows == [
        (
            "SWE-bench Verified",
            "gpt-4.1",
            "50.0 [15.0, 85.0] 2/4",
            "[1]",
            "–",
            "–",
            "–",
            "25.0 [4.6, 69.9] 1/4",
            "[1]",
            "–",
            "1.0000",
            "1.0000",
            "33.3 [6.1, 79.2] 1/3",
            "[2]",
            "–",
            "1.0000",
            "1.0000",
        )
    ]
    note = _table(report, "paper_main").note
    assert note.endswith(f"[1] {SUBSET}. [2] temperature 0.5, the paper used 0.")
    assert "mini_swe arms stand in the ReAct column" in note


def test_the_fixture_benchmark_is_in_the_success_table_but_never_beside_the_papers_numbers(report):
    splits = [(r["env_split"], r["arm"], r["episodes"], r["successes"]) for r in report.results["success_by_split"].dicts()]
    assert ("swe/custom", "recap", 2, 1) in splits
    assert all(r[0] == "SWE-bench Verified" for r in report.results["paper_table_main"].rows)
    assert not any("swe/custom" in str(v) or v == "swe" for r in report.results["paper_table_main"].rows for v in r)


def test_the_full_500_at_temperature_0_stands_beside_the_papers_numbers(full_run):
    rep = build_report([full_run], ReportOptions(formats=("csv",)))
    main = rep.results["paper_table_main"]
    assert main.columns == [
        "benchmark",
        "model",
        "recap",
        "recap:paper",
        "recap:diff",
        "recap:p",
        "recap:holm",
        "mini_swe",
        "mini_swe:paper",
        "mini_swe:diff",
        "mini_swe:p",
        "mini_swe:holm",
    ]
    row = main.rows[0]
    assert row[:5] == ("SWE-bench Verified", "gpt-4.1", "44.8 [40.5, 49.2] 224/500", "44.8", "0.0")
    assert row[7:10] == ("39.6 [35.4, 44.0] 198/500", "39.58", "0.0")
    assert not re.search(r"\[\d\]", _table(rep, "paper_main").note)


@pytest.mark.parametrize(
    ("change", "why"),
    [
        ({}, None),
        ({"test_double": True}, "a test double, not a language model"),
        ({"provider_model": "gpt-4.1"}, None),
        ({"provider_model": "openai/gpt-4.1-mini"}, "model openai/gpt-4.1-mini, the paper used GPT-4.1 (2025-04-14)"),
        ({"provider_model": "openai/gpt-4o-2024-08-06"}, "model openai/gpt-4o-2024-08-06, the paper used GPT-4.1 (2025-04-14)"),
        ({"profile": "released"}, "profile released, the paper's runs are profile paper"),
        ({"temperatures": (None,)}, "temperature none, the paper used 0"),
        ({"temperatures": (0.0, 0.7)}, "temperature 0, 0.7, the paper used 0"),
        ({"instances": 499, "episodes": 499}, "ran 499 of the paper's 500 instances (a subset)"),
        ({"episodes": 1000}, "1000 episodes over 500 instances, the paper ran each instance once (pass@1)"),
    ],
)
def test_the_swe_protocol_names_the_first_difference(change, why):
    arm = paper.ArmProtocol(
        provider_model="openai/gpt-4.1-2025-04-14",
        test_double=False,
        profile="paper",
        windows=(None,),
        benchmark="swe-verified",
        split="test",
        tasks=(),
        method="mini_swe",
        episodes=500,
        instances=500,
        temperatures=(0.0,),
    )
    assert paper.mismatch(paper.PROTOCOLS["main"], dataclasses.replace(arm, **change)) == why


def test_mini_swe_and_react_take_the_react_number_only_on_swe_verified():
    assert paper.main_reference("swe-verified/test", "mini_swe") == 39.58
    assert paper.main_reference("swe-verified/test", "react") == 39.58
    assert paper.main_reference("swe-verified/test", "recap") == 44.8
    assert paper.main_reference("swe/custom", "recap") is None
    assert paper.main_reference("fever/dev", "mini_swe") is None


def test_the_outcome_table_counts_evaluation_reasons_and_unevaluated_end_reasons(report):
    t = _table(report, "coding_outcomes")
    assert [c.key for c in t.columns] == [
        "model",
        "arm",
        "benchmark",
        "episodes",
        "resolved",
        "tests_failed",
        "patch_failed",
        "no_patch",
        "timeout",
        "no evaluation: budget_exhausted",
        "no evaluation: json_failures",
        "no evaluation: llm_error",
        "cost_usd",
    ]
    zero = dict.fromkeys((c.key for c in t.columns[3:-1]), 0)
    assert_rows(
        t.rows,
        [
            {"arm": "recap", "benchmark": "swe", **zero, "episodes": 2, "resolved": 1, "tests_failed": 1, "cost_usd": 0.0},
            {
                "arm": "mini_swe",
                "benchmark": "swe-verified",
                **zero,
                "episodes": 4,
                "resolved": 1,
                "tests_failed": 1,
                "patch_failed": 1,
                "no evaluation: llm_error": 1,
                "cost_usd": 4.75,
            },
            {
                "arm": "react",
                "benchmark": "swe-verified",
                **zero,
                "episodes": 4,
                "resolved": 1,
                "timeout": 1,
                "no evaluation: budget_exhausted": 1,
                "no evaluation: json_failures": 1,
                "cost_usd": 5.85,
            },
            {
                "arm": "recap",
                "benchmark": "swe-verified",
                **zero,
                "episodes": 4,
                "resolved": 2,
                "tests_failed": 1,
                "no_patch": 1,
                "cost_usd": 7.75,
            },
        ],
    )


def test_the_grading_table_counts_disagreements_between_ours_and_the_official_harness(report):
    t = _table(report, "coding_grading")
    assert_rows(
        t.rows,
        [
            {"arm": "recap", "benchmark": "swe", "judged": 2, "official_graded": 0, "disagreements": 0, "disagreeing": []},
            {
                "arm": "mini_swe",
                "benchmark": "swe-verified",
                "judged": 3,
                "official_graded": 2,
                "ours_resolved": 2,
                "official_resolved": 1,
                "disagreements": 1,
                "ours_only": 1,
                "official_only": 0,
                "disagreeing": ["swe-verified/django__django-4"],
            },
            {"arm": "react", "benchmark": "swe-verified", "judged": 2, "official_graded": 1, "disagreements": 0},
            {"arm": "recap", "benchmark": "swe-verified", "judged": 4, "official_graded": 3, "disagreements": 0},
        ],
    )
    assert t.note.startswith("Ours and the official harness disagree on 1 of the 6 episodes both graded.")


def test_the_calls_and_cost_plot_has_a_dot_per_finished_episode(report):
    svg = _plot(report, "coding_calls_cost").svg
    dots = re.findall(r'data-series="([^"]+)" data-x="([^"]+)" data-y="([^"]+)" data-filled="(\w+)"', svg)
    got = sorted((s, float(x), float(y), f == "true") for s, x, y, f in dots)
    assert got == sorted(
        [
            ("recap · swe", 4.0, 0.0, True),
            ("recap · swe", 6.0, 0.0, False),
            ("mini_swe · swe-verified", 5.0, 0.25, True),
            ("mini_swe · swe-verified", 8.0, 0.5, False),
            ("mini_swe · swe-verified", 40.0, 1.0, False),
            ("mini_swe · swe-verified", 250.0, 3.0, False),
            ("react · swe-verified", 15.0, 0.75, False),
            ("react · swe-verified", 20.0, 1.5, True),
            ("react · swe-verified", 2.0, 0.1, False),
            ("recap · swe-verified", 3.0, 0.5, True),
            ("recap · swe-verified", 12.0, 1.25, False),
            ("recap · swe-verified", 120.0, 4.0, True),
            ("recap · swe-verified", 30.0, 2.0, False),
        ]
    )
    # the capped episode (budget_exhausted) is a unit that did not finish: in the outcome table, not here
    assert "django__django-2" not in {r["instance_id"] for r in report.results["coding_episodes"].dicts() if r["arm"] == "react"}


def test_the_resolve_rate_plot_bins_tool_calls_per_method(report):
    rows = [
        (r["arm"], r["benchmark"], r["bin"], r["episodes"], r["resolved"])
        for r in report.results["coding_resolve_by_calls"].dicts()
    ]
    assert rows == [
        ("recap", "swe", "0-9", 2, 1),
        ("mini_swe", "swe-verified", "0-9", 2, 1),
        ("mini_swe", "swe-verified", "25-49", 1, 0),
        ("mini_swe", "swe-verified", "200+", 1, 0),
        ("react", "swe-verified", "0-9", 1, 0),
        ("react", "swe-verified", "10-24", 2, 1),
        ("recap", "swe-verified", "0-9", 1, 1),
        ("recap", "swe-verified", "10-24", 1, 0),
        ("recap", "swe-verified", "25-49", 1, 0),
        ("recap", "swe-verified", "100-199", 1, 1),
    ]
    svg = _plot(report, "coding_resolve_by_calls").svg
    bars = re.findall(r'<rect class="bar[^"]*"[^>]*><title>([^<]+)</title>', svg)
    assert len(bars) == 10
    assert "100-199 / recap · swe-verified: 100.0 [20.7, 100.0]" in bars
    assert "200+ / mini_swe · swe-verified: 0.0 [0.0, 79.3]" in bars
    t = _table(report, "coding_resolve_by_calls")
    assert [r["bin"] for r in t.rows] == ["0-9", "10-24", "25-49", "100-199", "200+"]
    assert t.rows[1]["react · swe-verified"][:2] == (1, 2)


def test_every_format_carries_the_coding_section(swe_run, tmp_path):
    rep = build_report([swe_run], ReportOptions(formats=FORMATS))
    write_report(rep, tmp_path, FORMATS)
    md = (tmp_path / "report.md").read_text()
    assert md.index("## Failure modes") < md.index("## Coding (SWE-bench)") < md.index("## The paper's tables")
    assert "![Tool calls and cost per episode](plots/coding_calls_cost.svg)" in md
    assert "| gpt-4.1 | mini_swe | swe-verified | 4 | 1 | 1 | 1 | 0 | 0 | 0 | 0 | 1 | $4.7500 |" in md
    for name in ("coding_calls_cost", "coding_resolve_by_calls"):
        assert (tmp_path / "plots" / f"{name}.svg").read_text() == _plot(rep, name).svg
    html = (tmp_path / "report.html").read_text()
    assert "Coding (SWE-bench)" in html and 'data-series="recap · swe-verified" data-x="120" data-y="4"' in html
    tex = (tmp_path / "tex" / "report.tex").read_text()
    for name in ("coding_outcomes", "coding_grading", "coding_distribution", "coding_resolve_by_calls"):
        assert f"\\input{{{name}}}" in tex and (tmp_path / "tex" / f"{name}.tex").is_file()
    episodes_csv = (tmp_path / "csv" / "coding_episodes.csv").read_text().splitlines()
    assert episodes_csv[0] == "model_label,arm,method,benchmark,instance_id,episode_id,resolved,tool_calls,cost_usd,end_reason"
    assert len(episodes_csv) == 1 + 13
    assert (
        "gpt-4.1,mini_swe,mini_swe,swe-verified,swe-verified/django__django-4,swe-verified-mini_swe-django__django-4-1,False,250,3.0,agent_done"
        in episodes_csv
    )
    for name in ("coding_outcomes", "coding_grading", "coding_distribution", "coding_resolve_by_calls", "paper_swe"):
        assert (tmp_path / "csv" / f"{name}.csv").is_file()


def test_a_run_without_coding_episodes_gets_no_coding_section_nor_its_files(run_a, tmp_path):
    rep = build_report([run_a], ReportOptions(formats=FORMATS))
    assert [s.key for s in rep.sections] == ["overview", "success", "costs", "context", "trees", "failures", "paper"]
    assert not [n for n in rep.results if n.startswith("coding_") or n == "paper_swe"]
    written = write_report(rep, tmp_path, FORMATS)
    assert not [p for p in written if "coding" in p.name or "swe" in p.name]


def test_recap_report_shows_the_coding_run(swe_run, tmp_path, capsys):
    rc = recap_main(["report", str(swe_run), "--format", "md", "--out", str(tmp_path / "rep")])
    out, err = capsys.readouterr()
    assert (rc, err) == (0, "")
    md = (tmp_path / "rep" / "report.md").read_text()
    assert "| SWE-bench Verified | gpt-4.1 | 50.0 [15.0, 85.0] 2/4 | [1] |" in md
    assert "### Coding episodes: how each ended (evaluation reason, or why it was never evaluated)" in md
