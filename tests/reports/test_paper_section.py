"""The paper section filled from the pipeline's own output: each examples/paper/ sweep, run through
``recap run`` on a local Ray with the offline expert (a test double) and one instance per task,
then every cell of every paper table checked against numbers derived here, independently, from
the run's Parquet rows (pyarrow + the reference statistics of reports/stats.py).

The quick tests check the paper's numbers and the protocol rule (:func:`reports.paper.mismatch`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest
import yaml

from reports import paper
from reports.build import ReportOptions, build_report
from reports.stats import cluster_wilson, clustered_mcnemar_exact, holm, instance_discordance, paired_permutation_p

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples" / "paper"
TEST_DOUBLE = "a test double, not a language model"


# -- the paper's numbers and the protocol rule (quick) -------------------------------------------------


def test_per_task_tables_average_to_their_average_rows_and_the_main_table():
    for split in ("synchronous", "asynchronous"):
        for method in paper.TASK_ORDER:
            mean = sum(paper.PER_TASK[split][i][method] for i in range(10)) / 10
            assert mean == paper.PER_TASK_AVERAGE[split][method] == paper.MAIN[("robotouille", split)][method]
    assert paper.PER_TASK["synchronous"][6] == {
        "recap": 70.0,
        "react": 50.0,
        "adapt": 20.0,
        "act": 20.0,
        "cot": 0.0,
        "standard": 0.0,
    }
    assert paper.PER_TASK["asynchronous"][9] == {
        "recap": 10.0,
        "react": 0.0,
        "adapt": 0.0,
        "act": 0.0,
        "cot": 0.0,
        "standard": 0.0,
    }


def _arm(**kw: Any) -> paper.ArmProtocol:
    base = dict(
        provider_model="openai/gpt-4o-2024-08-06",
        test_double=False,
        profile="paper",
        windows=(128,),
        benchmark="robotouille",
        split="synchronous",
        tasks=tuple((f"{i}_t", (paper.step_multiplier("synchronous", i),)) for i in range(10)),
    )
    return paper.ArmProtocol(**{**base, **kw})


def test_mismatch_names_the_first_protocol_difference():
    main = paper.PROTOCOLS["main"]
    assert paper.mismatch(main, _arm()) is None
    assert paper.mismatch(main, _arm(test_double=True)) == TEST_DOUBLE
    assert paper.mismatch(main, _arm(provider_model="gpt-4o-mini")) == "model gpt-4o-mini, the paper used GPT-4o"
    assert paper.mismatch(main, _arm(provider_model="gpt-4o-2024-11-20")) == "model gpt-4o-2024-11-20, the paper used GPT-4o"
    assert paper.mismatch(main, _arm(profile="released")) == "profile released, the paper's runs are profile paper"
    # windows count messages: ReCAP 128 (K = 64 rounds), the released ReAct 64 on Robotouille and
    # 128 on ALFWorld; Act keeps its whole history, so its window is not checked
    assert paper.mismatch(main, _arm(windows=(64,))) == "window 64 messages, the paper used 128"
    react_tasks = tuple((f"{i}_t", (paper.step_multiplier("synchronous", i, "react"),)) for i in range(10))
    assert paper.mismatch(main, _arm(method="react", windows=(64,), tasks=react_tasks)) is None
    assert paper.mismatch(main, _arm(method="react", windows=(128,), tasks=react_tasks)) == (
        "window 128 messages, the paper used 64"
    )
    act_tasks = tuple((f"{i}_t", (2.0,)) for i in range(10))
    assert paper.mismatch(main, _arm(method="act", windows=(128,), tasks=act_tasks)) is None
    # step caps per method and task (the released configs): ReAct x2 on synchronous 9, Act x2
    assert [paper.step_multiplier("synchronous", i, "react") for i in range(10)] == [4, 4, 3, 4, 3, 4, 3, 4, 4, 2]
    assert [paper.step_multiplier("asynchronous", i, "react") for i in range(10)] == [4, 4, 2, 4, 3, 4, 3, 4, 4, 4]
    assert [paper.step_multiplier("asynchronous", i, "recap") for i in range(10)] == [4] * 10
    assert {
        paper.step_multiplier(s, i, m) for s in ("synchronous", "asynchronous") for i in range(10) for m in ("adapt", "cot")
    } == {4}
    assert paper.step_multiplier("synchronous", 3, "standard") == 1.5
    assert paper.mismatch(main, _arm(method="act", tasks=react_tasks)) == (
        "step cap x4 on synchronous:0, the released configs use x2"
    )
    assert paper.mismatch(main, _arm(tasks=(("2_t", (3.0,)), ("6_t", (3.0,))))) == (
        "ran 2 of the paper's 10 tasks (missing synchronous:0, synchronous:1, synchronous:3, synchronous:4, "
        "synchronous:5, synchronous:7, synchronous:8, synchronous:9)"
    )
    all_x4 = tuple((f"{i}_t", (4.0,)) for i in range(10))
    assert paper.mismatch(main, _arm(tasks=all_x4)) == "step cap x4 on synchronous:2, the released configs use x3"
    cross = paper.PROTOCOLS["cross_model"]
    t246 = tuple((f"{i}_t", (3.0,)) for i in (2, 4, 6))
    assert paper.mismatch(cross, _arm(tasks=t246)) == "window 128 messages, the paper used 64"
    assert paper.mismatch(cross, _arm(tasks=t246, windows=(64,), method="react")) is None
    cross_arm = {"windows": (64,)}
    assert (
        paper.mismatch(cross, _arm(tasks=t246, provider_model="together_ai/Qwen/Qwen2.5-72B-Instruct-Turbo", **cross_arm)) is None
    )
    assert (
        paper.mismatch(
            cross, _arm(tasks=t246, provider_model="deepinfra/meta-llama/Llama-4-Maverick-17B-128E-Instruct-FP8", **cross_arm)
        )
        is None
    )
    assert (
        paper.mismatch(cross, _arm(tasks=t246 + (("7_t", (4.0,)),), **cross_arm))
        == "ran tasks the paper's number leaves out (synchronous:7)"
    )
    labels = tuple((label, (4.0,)) for label in paper.FEVER_LABELS)
    fever = _arm(benchmark="fever", split="dev", tasks=labels, episodes=200)
    assert paper.mismatch(main, fever) is None
    assert paper.mismatch(main, _arm(benchmark="fever", split="dev", tasks=labels, episodes=3)) == ("3 claims, the paper ran 200")
    # FEVER's numbers came from the released code: ReCAP's released window (32 messages,
    # chatbot.py:42-44) is the paper's there; the notebooks' ReAct keeps its whole history
    released = dict(benchmark="fever", split="dev", tasks=labels, episodes=200, profile="released")
    assert paper.mismatch(main, _arm(windows=(32,), **released)) is None
    assert paper.mismatch(main, _arm(windows=(128,), **released)) == "window 128 messages, the paper used 32"
    assert paper.mismatch(main, _arm(method="react", windows=(100000,), **released)) is None
    assert paper.main_reference("fever/dev", "recap") == 63.5 and paper.main_reference("fever/dev", "adapt") is None
    alf = _arm(benchmark="alfworld", split="valid_unseen", tasks=tuple((t, (4.0,)) for t in paper.ALFWORLD_TYPES))
    assert paper.mismatch(main, alf) is None
    assert paper.mismatch(main, alf, ["heat"]) == "ran tasks the paper's number leaves out (clean, cool, examine, put, puttwo)"


# -- the examples, run small -----------------------------------------------------------------------

EXPERT = {"model": "offline/expert", "options": {"seed": 7, "invalid_action_rate": 0.15, "malformed_json_rate": 0.05}}


def derived_spec(name: str, out: Path) -> tuple[dict[str, Any], Path]:
    """examples/paper/<name>.yaml with the protocol kept (methods, profiles, windows, ablations,
    step multiplier, seeds, the tasks) and three changes: each model becomes the offline expert
    under the same label, each task selector names one task and runs its first instance only,
    and the output is ``out``."""
    spec = yaml.safe_load((EXAMPLES / f"{name}.yaml").read_text())
    models = []
    for i, m in enumerate(spec["models"]):
        models.append({**EXPERT, "label": m.get("label") or m["model"], "options": {**EXPERT["options"], "seed": 7 + i}})
    envs = []
    for e in spec["environments"]:
        tasks = []
        for sel in e["tasks"]:
            if sel in ("synchronous", "asynchronous"):
                tasks += [f"{sel}/{i}" for i in range(10)]
            elif sel == "all":
                tasks += list(paper.ALFWORLD_TYPES)
            else:
                tasks.append(sel)
        envs.append({"benchmark": e["benchmark"], "tasks": tasks, "limit": 1})
    spec.update(run=spec["run"] + "-small", output=str(out), models=models, environments=envs, workers=4, run_cap_usd=None)
    spec.pop("run_cap_usd")
    path = out.parent / f"{name}.yaml"
    path.write_text(yaml.safe_dump(spec, sort_keys=False))
    return spec, path


def _read(run_dir: Path, table: str) -> list[dict[str, Any]]:
    files = sorted((run_dir / table).glob("*.parquet"))
    return [r for f in files for r in pq.read_table(f).to_pylist()]


def unit_rows(run_dir: Path) -> list[dict[str, Any]]:
    """One row per unit that finished on its own merits: its latest such attempt."""
    best: dict[str, dict[str, Any]] = {}
    for r in _read(run_dir, "episodes"):
        if r["end_reason"] in ("budget_exhausted", "infra_error"):
            continue
        cur = best.get(r["unit_id"])
        if cur is None or r["attempt"] > cur["attempt"]:
            best[r["unit_id"]] = r
    return list(best.values())


def label_of(r: dict[str, Any]) -> str:
    return r["model"] + (" (test double)" if r["test_double"] else "")


def rate(rows: list[dict[str, Any]]) -> tuple[int, int, float, float]:
    by_inst: dict[str, list[bool]] = {}
    for r in rows:
        by_inst.setdefault(f"{r['split']}/{r['task']}/{r['instance_id']}", []).append(r["success"])
    lo, hi = cluster_wilson([(sum(v), len(v)) for v in by_inst.values()])
    return (sum(r["success"] for r in rows), len(rows), lo, hi)


def mcnemar(arm: list[dict[str, Any]], ref: list[dict[str, Any]]) -> float | None:
    key = lambda r: (r["split"], r["task"], r["instance_id"], r["sampling_seed"])  # noqa: E731
    refs = {key(r): r["success"] for r in ref}
    paired = [r for r in arm if key(r) in refs]
    if not paired:
        return None
    # the arms are swapped per instance, all its seeds together (the clustered McNemar test)
    inst = [key(r)[:3] for r in paired]
    return float(
        clustered_mcnemar_exact(instance_discordance([refs[key(r)] for r in paired], [r["success"] for r in paired], inst))
    )


def assert_rate(got: Any, want: tuple[int, int, float, float]) -> None:
    assert got[:2] == want[:2]
    assert got[2] == pytest.approx(want[2], abs=1e-9) and got[3] == pytest.approx(want[3], abs=1e-9)


def assert_p(got: Any, want: float | None) -> None:
    assert (got is None) == (want is None), (got, want)
    if want is not None:
        assert got == pytest.approx(want, abs=1e-9)


def _paper_run(base: Path, name: str) -> Path:
    """One example protocol of examples/paper/, derived small, run through ``recap run``."""
    from pipeline.cli import main

    out = base / "runs" / name
    out.parent.mkdir(parents=True, exist_ok=True)
    _, path = derived_spec(name, out)
    assert main(["run", str(path), "--progress", "off"]) == 0, name
    return out


# one fixture per example protocol, each read by one test, so pytest-xdist spreads the sweeps
# over its workers instead of making all four on one
@pytest.fixture(scope="module")
def main_runs(ray_address, tmp_path_factory) -> list[Path]:
    base = tmp_path_factory.mktemp("paper")
    return [_paper_run(base, "main-robotouille"), _paper_run(base, "main-alfworld")]


@pytest.fixture(scope="module")
def cross_run(ray_address, tmp_path_factory) -> Path:
    return _paper_run(tmp_path_factory.mktemp("paper"), "cross-model")


@pytest.fixture(scope="module")
def ablation_run(ray_address, tmp_path_factory) -> Path:
    return _paper_run(tmp_path_factory.mktemp("paper"), "ablations")


def _cells(row: dict[str, Any], key: str) -> dict[str, Any]:
    return {
        k: row.get(f"{key}{s}") for k, s in (("ours", ""), ("paper", ":paper"), ("diff", ":diff"), ("p", ":p"), ("holm", ":holm"))
    }


def _rate_keys(keys: list[str]) -> list[str]:
    out = []
    for k in keys:
        out += [k, f"{k}:paper", f"{k}:diff", f"{k}:p", f"{k}:holm"]
    return out


def _check_holm(t, keys: list[str]) -> None:
    slots = [(r, k) for r in t.rows for k in keys if r.get(f"{k}:p") is not None]
    for (r, k), a in zip(slots, holm([r[f"{k}:p"] for r, k in slots])):
        assert r[f"{k}:holm"] == pytest.approx(a)
    assert f"; {len(slots)} comparisons (Holm over the table)." in t.note


# ~3 minutes of one test worker (six methods x twenty Robotouille tasks and six ALFWorld types through
# the whole pipeline): in the slow suite (`bash scripts/test.sh slow`); the cross-model and ablation
# protocols below take the same paper-section path from a real sweep in the default suite
@pytest.mark.slow
def test_paper_section_from_the_main_protocols(main_runs, tmp_path):
    main_dirs = main_runs
    report = build_report(main_dirs, ReportOptions(formats=("md",), paper_only=True))
    assert [s.key for s in report.sections] == ["paper"]
    tables = {t.name: t for t in report.sections[0].tables}
    units = [r for d in main_dirs for r in unit_rows(d)]
    assert {r["model"] for r in units} == {"gpt-4o"} and all(r["test_double"] for r in units)
    model = "gpt-4o (test double)"
    # no cross-model table from the main runs: their ReAct keeps 64 messages on Robotouille (the
    # released baseline) but their ReCAP 128 (K = 64 rounds), so no model has both at 64
    assert list(tables) == [
        "paper_main",
        "paper_tasks_synchronous_gpt_4o_test_double",
        "paper_tasks_asynchronous_gpt_4o_test_double",
        "paper_costs_alfworld",
        "paper_cost_ratio",
        "paper_costs_task6",
        "paper_trees",
        "paper_omitted",
    ]

    # main table: rows ALFWorld, Sync, Async; columns in the paper's method order
    t = tables["paper_main"]
    order = ["recap", "adapt", "react", "cot", "act", "standard"]
    assert [c.key for c in t.columns] == ["benchmark", "model"] + _rate_keys(order)
    assert [(r["benchmark"], r["model"]) for r in t.rows] == [
        ("ALFWorld", model),
        ("Robotouille (Sync)", model),
        ("Robotouille (Async)", model),
    ]
    for row, (bench, split) in zip(
        t.rows, (("alfworld", "valid_unseen"), ("robotouille", "synchronous"), ("robotouille", "asynchronous"))
    ):
        here = [r for r in units if (r["benchmark"], r["split"]) == (bench, split)]
        ref = [r for r in here if r["label"] == "recap"]
        for label in order:
            cell = _cells(row, label)
            mine = [r for r in here if r["label"] == label]
            if not mine:  # CoT and Standard do not run on ALFWorld
                assert bench == "alfworld" and label in ("cot", "standard") and cell == dict.fromkeys(cell)
                continue
            assert_rate(cell["ours"], rate(mine))
            # ADaPT's ALFWorld number is GPT-3.5 from another paper: never comparable
            assert cell["paper"] == ("[2]" if (bench, label) == ("alfworld", "adapt") else "[1]") and cell["diff"] is None
            assert_p(cell["p"], None if label == "recap" else mcnemar(mine, ref))
    _check_holm(t, order)
    assert t.note.endswith(f"[1] {TEST_DOUBLE}. [2] {paper.FOREIGN[('alfworld', 'adapt')]}.")

    # per-task tables: the benchmark's tasks in order, then Average; the paper's per-task order
    task_order = ["recap", "react", "adapt", "act", "cot", "standard"]
    for split, n_tasks in (("synchronous", 10), ("asynchronous", 10)):
        t = tables[f"paper_tasks_{split}_gpt_4o_test_double"]
        assert [c.key for c in t.columns] == ["task"] + _rate_keys(task_order)
        here = [r for r in units if r["benchmark"] == "robotouille" and r["split"] == split]
        tasks = sorted({r["task"] for r in here}, key=paper.task_index)
        assert len(tasks) == n_tasks and [r["task"] for r in t.rows] == tasks + ["Average"]
        for row in t.rows:
            scope = here if row["task"] == "Average" else [r for r in here if r["task"] == row["task"]]
            for label in task_order:
                cell = _cells(row, label)
                mine = [r for r in scope if r["label"] == label]
                assert_rate(cell["ours"], rate(mine))
                assert cell["paper"] == "[1]" and cell["diff"] is None
                assert_p(cell["p"], None if label == "recap" else mcnemar(mine, [r for r in scope if r["label"] == "recap"]))
        _check_holm(t, task_order)
        # step caps: each method at its released multiplier on each task (recorded on every row)
        assert {(r["task"], r["label"], r["step_multiplier"]) for r in here} == {
            (task, label, paper.step_multiplier(split, paper.task_index(task), label)) for task in tasks for label in task_order
        }
        assert all(r["step_cap"] == math.ceil(r["optimal_steps"] * r["step_multiplier"]) for r in here)

    # ALFWorld costs: totals per method, paired permutation p against ReCAP; the ReCAP/ReAct ratio
    alf = [r for r in units if r["benchmark"] == "alfworld"]
    assert sorted({r["task"] for r in alf}) == list(paper.ALFWORLD_TYPES)
    t = tables["paper_costs_alfworld"]
    assert [r["method"] for r in t.rows] == ["recap", "adapt", "react", "act"]
    key = lambda r: (r["task"], r["instance_id"], r["sampling_seed"])  # noqa: E731
    recap_cost = {key(r): r["cost_usd"] for r in alf if r["label"] == "recap"}
    for row in t.rows:
        mine = [r for r in alf if r["label"] == row["method"]]
        assert (row["model"], row["games"], row["calls"], row["tokens"]) == (
            model,
            len(mine),
            sum(r["llm_calls"] for r in mine),
            sum(r["prompt_tokens"] + r["completion_tokens"] for r in mine),
        )
        assert row["cost"] == pytest.approx(sum(r["cost_usd"] for r in mine)) and row["per_game"] == pytest.approx(
            row["cost"] / len(mine)
        )
        assert row.get("paper") == ("[1]" if row["method"] in paper.COSTS["alfworld_134_games_usd"] else None)
        assert row.get("diff") is None
        both = [r for r in sorted(mine, key=key) if key(r) in recap_cost]
        diffs = [r["cost_usd"] - recap_cost[key(r)] for r in both]
        # signs flipped per instance (all its seeds together)
        assert_p(row["p"], None if row["method"] == "recap" else paired_permutation_p(diffs, [key(r)[:2] for r in both]))
    (ratio,) = tables["paper_cost_ratio"].rows
    react = sorted((r for r in alf if r["label"] == "react"), key=key)
    assert (ratio["games"], ratio["paper"]) == (len(react), "[1]")
    assert ratio["ratio"] == pytest.approx(sum(recap_cost[key(r)] for r in react) / sum(r["cost_usd"] for r in react))
    assert ratio["p"] == pytest.approx(
        paired_permutation_p([r["cost_usd"] - recap_cost[key(r)] for r in react], [key(r)[:2] for r in react])
    )

    # task-6 costs and trees from the main runs (ReAct 64 messages, the others 128): no paper number (test double)
    t6 = [r for r in units if r["split"] == "synchronous" and paper.task_index(r["task"]) == 6]
    t = tables["paper_costs_task6"]
    assert [r["method"] for r in t.rows] == ["recap", "adapt", "react", "cot", "act", "standard"]
    for row in t.rows:
        (mine,) = [r for r in t6 if r["label"] == row["method"]]
        assert (row["episodes"], row["calls"], row["cost"], row["window"]) == (
            1,
            mine["llm_calls"],
            pytest.approx(mine["cost_usd"]),
            "64" if row["method"] == "react" else "128",
        )
        assert row.get("paper_calls") == ("[1]" if row["method"] == "recap" else None)
    (tree_row,) = tables["paper_trees"].rows
    (recap6,) = [r for r in t6 if r["label"] == "recap"]
    check_tree(tree_row, [recap6], _read(main_runs[0], "tree_nodes"))

    # what these runs do not hold: one line each
    assert tables["paper_omitted"].rows == [
        {"table": "FEVER by label", "missing": "no arm without an ablation ran FEVER claims."},
        {
            "table": "Cross-model table",
            "missing": "no model has both a ReAct and a ReCAP arm without an ablation on Robotouille synchronous tasks 2, "
            "4, 6 with a 64-message window.",
        },
        {"table": "Ablation table", "missing": "no ReCAP ablation ran Robotouille synchronous task 6 with a 128-message window."},
    ]

    # every format renders the section (recap report --paper)
    from pipeline.cli.report import report_main

    out = tmp_path / "report"
    assert report_main([*map(str, main_dirs), "--paper", "--out", str(out), "--viewer-max", "0"]) == 0
    md = (out / "report.md").read_text()
    assert "\n## The paper's tables\n" in md and "\n## Success rates\n" not in md
    assert "| ALFWorld | gpt-4o (test double) |" in md
    assert (out / "tex" / "paper_main.tex").is_file() and (out / "csv" / "paper_table_main.csv").is_file()
    assert "paper_main" in (out / "report.html").read_text()


def check_tree(row: dict[str, Any], episodes: list[dict[str, Any]], nodes: list[dict[str, Any]]) -> None:
    levels, branching = [], []
    for ep in episodes:
        mine = [n for n in nodes if n["episode_id"] == ep["episode_id"]]
        levels.append(max(n["depth"] for n in mine) + 1)
        kids: dict[int, int] = {}
        for n in mine:
            if n["parent_id"] is not None:
                kids[n["parent_id"]] = kids.get(n["parent_id"], 0) + 1
        branching.append(sum(kids.values()) / len(kids))
    assert row["episodes"] == len(episodes)
    assert row["levels"] == pytest.approx(sum(levels) / len(levels))
    assert row["branching"] == pytest.approx(sum(branching) / len(branching))
    if len(levels) > 1:
        mean = sum(levels) / len(levels)
        assert row["levels_sd"] == pytest.approx(math.sqrt(sum((x - mean) ** 2 for x in levels) / (len(levels) - 1)))


def test_paper_section_from_the_cross_model_protocol(cross_run):
    # the cross-model example
    report = build_report([cross_run], ReportOptions(formats=("md",), paper_only=True))
    tables = {t.name: t for t in report.sections[0].tables}
    assert [r["table"] for r in tables["paper_omitted"].rows] == [
        "Per-task table (asynchronous)",
        "FEVER by label",
        "Ablation table",
        "ALFWorld costs",
    ]
    cross = unit_rows(cross_run)
    t = tables["paper_cross_model"]
    models = [
        "gpt-4o (test double)",
        "qwen2.5-32b (test double)",
        "qwen2.5-72b (test double)",
        "llama-4-maverick (test double)",
        "deepseek-v3 (test double)",
    ]
    assert [c.key for c in t.columns] == ["method"] + _rate_keys(models)  # the paper's model order
    assert [r["method"] for r in t.rows] == ["react", "recap"]
    for row in t.rows:
        for m in models:
            cell = _cells(row, m)
            mine = [r for r in cross if label_of(r) == m and r["label"] == row["method"]]
            assert len(mine) == 3 and {paper.task_index(r["task"]) for r in mine} == {2, 4, 6}
            assert_rate(cell["ours"], rate(mine))
            assert cell["paper"] == "[1]" and cell["diff"] is None
            ref = [r for r in cross if label_of(r) == m and r["label"] == "recap"]
            assert_p(cell["p"], None if row["method"] == "recap" else mcnemar(mine, ref))
    _check_holm(t, models)


def test_paper_section_from_the_ablation_protocol(ablation_run):
    model = "gpt-4o (test double)"
    # the ablation example
    report = build_report([ablation_run], ReportOptions(formats=("md",), paper_only=True))
    tables = {t.name: t for t in report.sections[0].tables}
    assert [r["table"] for r in tables["paper_omitted"].rows] == [
        "Per-task table (asynchronous)",
        "FEVER by label",
        "Cross-model table",
        "ALFWorld costs",
    ]
    abl = unit_rows(ablation_run)
    t = tables["paper_ablations"]
    variants = list(paper.ABLATIONS)
    assert [c.key for c in t.columns] == ["model", "profile"] + _rate_keys(variants)
    (row,) = t.rows
    assert (row["model"], row["profile"]) == (model, "paper")
    original = [r for r in abl if r["ablation"] is None]
    assert len(original) == 2 and {r["sampling_seed"] for r in original} == {0, 1}
    for v in variants:
        cell = _cells(row, v)
        mine = original if v == "original" else [r for r in abl if r["ablation"] == v]
        assert len(mine) == 2 and all(r["label"] == ("recap" if v == "original" else f"recap-{v}") for r in mine)
        assert_rate(cell["ours"], rate(mine))
        assert cell["paper"] == "[1]" and cell["diff"] is None
        assert_p(cell["p"], None if v == "original" else mcnemar(mine, original))
    _check_holm(t, variants)
    (tree_row,) = tables["paper_trees"].rows
    assert (tree_row["window"], tree_row["paper_depth"], tree_row["paper_branching"]) == ("128", "[1]", "[1]")
    check_tree(tree_row, original, _read(ablation_run, "tree_nodes"))
