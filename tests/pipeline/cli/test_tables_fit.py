"""Terminal tables fit the terminal by leaving columns out, never by cutting a name (issue 36 item
10: at 100 columns ``recap estimate`` printed the ablation arms as ``recap…``); ``--dry-run`` prints
the plan per arm and benchmark with its new / unchanged / changed units."""

from __future__ import annotations

import dataclasses

import pytest

from pipeline.cli import main
from pipeline.tables import Col, fitted_table

#: arm labels as long as the ablations' (each its own method: identical settings would be refused)
METHODS = {
    "recap-think_many": "recap",
    "react-released_all": "react",
    "act-history_last": "act",
    "cot-no_repairs": "cot",
    "recap-level_2": "adapt",
}
ARMS = tuple(METHODS)
SWEEP = """run: fit
output: {out}
models:
  - model: gpt-4o
  - model: offline/expert
    label: expert-noisy
methods:
{methods}
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
"""


def _spec(tmp_path):
    methods = "\n".join(f"  - {{method: {method}, label: {arm}}}" for arm, method in METHODS.items())
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=tmp_path / "run", methods=methods))
    return spec


def _table_lines(out: str) -> list[str]:
    return [line for line in out.splitlines() if line.startswith(("┃", "│", "┏", "└"))]


@pytest.mark.parametrize("columns", [100, 80])
def test_estimate_keeps_every_arm_name_whole(tmp_path, capsys, monkeypatch, columns):
    monkeypatch.setenv("COLUMNS", str(columns))
    assert main(["estimate", str(_spec(tmp_path))]) == 0
    out = capsys.readouterr().out
    lines = _table_lines(out)
    assert "…" not in out
    assert all(len(line) <= columns for line in lines), max(len(x) for x in lines)
    names = [line.split("│")[1].strip() for line in lines if line.startswith("│")]
    assert names == [arm for arm in ARMS for _ in range(2)]  # every arm, whole, for each model
    assert "left out to fit" in out and "cost $" in out  # the cost stays, lower-value columns go


@pytest.mark.parametrize("columns", [100, 80])
def test_dry_run_prints_the_plan_per_arm_and_benchmark(tmp_path, capsys, monkeypatch, columns):
    monkeypatch.setenv("COLUMNS", str(columns))
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test")  # a dry run checks the keys; it calls nothing
    assert main(["run", str(_spec(tmp_path)), "--dry-run"]) == 0
    out = capsys.readouterr().out
    assert "plan of run fit" in out and "…" not in out
    rows = [[c.strip() for c in line.split("│")[1:-1]] for line in _table_lines(out) if line.startswith("│")]
    assert [r[:3] for r in rows] == [
        [arm, model, "blocksworld"] for arm in ARMS for model in ("gpt-4o", "expert-noisy (test double)")
    ]
    assert all(len(line) <= columns for line in _table_lines(out))


def test_plan_rows_count_new_unchanged_and_changed(tmp_path):
    from pipeline.cli.run import plan_rows
    from pipeline.prepare import prepare
    from pipeline.spec import load_spec
    from pipeline.units import PlanDiff

    spec, text = load_spec(_spec(tmp_path))
    prepared = prepare(spec, text, check_keys=False)
    keys = [u.key for u in prepared.plan.units if u.method_label == "recap-level_2" and u.model_label == "gpt-4o"]
    assert len(keys) > 2
    diff = PlanDiff(new=keys[2:], unchanged=keys[:1], changed=keys[1:2], removed=[])
    rows = plan_rows(dataclasses.replace(prepared, diff=diff))
    row = next(r for r in rows if r[:2] == ["recap-level_2", "gpt-4o"])
    assert row == ["recap-level_2", "gpt-4o", "blocksworld", str(len(keys)), str(len(keys) - 2), "1", "1"]
    fresh = next(r for r in plan_rows(prepared) if r[:2] == ["recap-level_2", "gpt-4o"])
    assert fresh[3:] == [str(len(keys)), str(len(keys)), "0", "0"]


def test_columns_go_lowest_rank_first_and_names_never():
    cols = [Col("arm", "left"), Col("a", drop=2), Col("b", drop=1), Col("c", drop=3)]
    rows = [["a-rather-long-arm-name", "1" * 10, "2" * 10, "3" * 10]]
    t = fitted_table("t", cols, rows, 60)
    assert [c.header for c in t.columns] == ["arm", "a", "c"]
    assert t.caption == "left out to fit 60 columns: b"
    t = fitted_table("t", cols, rows, 10)  # nothing but the name fits: every other column goes, the name stays
    assert [c.header for c in t.columns] == ["arm"]
