"""The paper's FEVER numbers stand beside an arm only over the sample behind them: main.py's seed 42
(ReCAP, CoT, Standard) or the notebooks' seed 233 (ReAct, Act)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import duckdb

from reports import paper
from reports.paper_cells import Cells
from reports.paper_rates import fever_sample_cell
from reports.sections.fever_samples import load_fever_samples, sample_indices, sample_rows
from workers.envs.fever.claims import paper_indices


def test_the_report_shuffles_as_the_benchmark_does():
    for seed in (42, 233):
        assert sample_indices(seed) == paper_indices(seed)
    assert paper.FEVER_SAMPLE_SEED == {"recap": 42, "cot": 42, "standard": 42, "react": 233, "act": 233}
    assert "108/200 = 54.0" in paper.FEVER_NOTE and "58.5" in paper.FEVER_NOTE


def _claims(folder: Path) -> Path:
    path = folder / "paper_dev.jsonl"
    path.write_text("".join(json.dumps({"id": 50_000 + i, "claim": "c", "label": "SUPPORTS"}) + "\n" for i in range(7405)))
    return path


def test_both_samples_are_loaded_with_the_claims_they_share(tmp_path, monkeypatch):
    rows = sample_rows(_claims(tmp_path))
    assert len(rows) == 400 and rows[0] == (f"fever/{50_000 + 1547}", 42) and rows[200] == (f"fever/{50_000 + 3687}", 233)
    ids = {seed: {i for i, s in rows if s == seed} for seed in (42, 233)}
    assert len(ids[42] & ids[233]) == 4
    con = duckdb.connect(":memory:")
    con.execute("CREATE TABLE fever_samples (instance_id VARCHAR, sample_seed BIGINT)")
    con.execute("CREATE TABLE outcomes (benchmark VARCHAR)")
    assert load_fever_samples(con) is False  # no FEVER episode: nothing read
    con.execute("INSERT INTO outcomes VALUES ('fever')")
    monkeypatch.setenv("FEVER_DATA", str(tmp_path))
    assert load_fever_samples(con) is True
    assert con.execute("SELECT sample_seed, count(*) FROM fever_samples GROUP BY 1 ORDER BY 1").fetchall() == [
        (42, 200),
        (233, 200),
    ]


def _cell(scope: str, method: str, episodes: int, successes: int, profile: str = "released") -> dict[str, Any]:
    return {
        "scope": scope,
        "level": "split",
        "model_label": "gpt-4o",
        "arm_label": method,
        "method": method,
        "ablation": "original",
        "benchmark": "fever",
        "split": "dev",
        "task": None,
        "profiles": [profile],
        "provider_models": ["openai/gpt-4o-2024-08-06"],
        "test_double": False,
        "windows": [None],
        "task_multipliers": [{"task": label, "multipliers": [1.0]} for label in paper.FEVER_LABELS],
        "episodes": episodes,
        "successes": successes,
        "instances": episodes,
    }


def _cells(rows: list[dict[str, Any]]) -> Cells:
    cells = Cells.__new__(Cells)
    cells.cells = rows
    return cells


def test_an_arm_is_compared_over_its_methods_paper_sample_only():
    whole = _cell("all", "act", 396, 210)
    seed_233 = _cell("fever_seed233", "act", 200, 108)
    seed_42 = _cell("fever_seed42", "act", 200, 102)
    cell, why = fever_sample_cell(_cells([whole, seed_42, seed_233]), whole)
    assert (cell, why) == (seed_233, None)
    recap_whole, recap_42 = _cell("all", "recap", 396, 250), _cell("fever_seed42", "recap", 200, 127)
    recap_42["windows"] = recap_whole["windows"] = [32]  # the released ReCAP window on FEVER
    assert fever_sample_cell(_cells([recap_whole, recap_42, _cell("fever_seed233", "recap", 200, 120)]), recap_whole) == (
        recap_42,
        None,
    )
    # only the other sample ran: no comparison, and why
    assert fever_sample_cell(_cells([whole, seed_42]), whole) == (whole, "none of the paper's sample for it (seed 233) ran")
    # part of the sample: the claims counted
    part = _cell("fever_seed233", "act", 150, 80)
    assert fever_sample_cell(_cells([whole, part]), whole)[1] == "150 claims, the paper ran 200 of its sample (seed 233)"
    # the samples unknown (no claims file when the report was built)
    assert fever_sample_cell(_cells([whole]), whole)[1] == (
        "the paper's sample (seed 233) cannot be told here: no paper_dev.jsonl (set FEVER_DATA)"
    )
    # a profile other than paper or released is not the paper's protocol
    other = _cell("fever_seed233", "act", 200, 108, profile="none")
    assert "profile none" in (fever_sample_cell(_cells([whole, other]), whole)[1] or "")
