"""Writes synthetic run folders of any size (for the report benchmark, or ``recap report`` without a sweep).

The rows follow the schemas (``schemas/tables.py``) and the run layout of ``schemas/parts.py``
(atomic ``part-<writer>-<n>.parquet`` files per table); the numbers are random but consistent:
an episode's calls, messages, steps and tree agree with its episode row, windows are bounded
like a sliding window of ``window`` messages after two pinned ones, and outcomes depend on the
method. Columns are built with NumPy so a million-message run takes seconds to write.

    python -m reports.synthetic OUT_DIR [--messages 1000000] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from recap.baselines.react import ReActConfig
from recap.config import ReCAPConfig
from schemas.labels import ALFWORLD_TASK_TYPES
from schemas.records import SCHEMA_VERSION
from schemas.tables import arrow_schema
from schemas.versions import column_defaults

METHODS = ("recap", "react", "act")
SPLITS = (("robotouille", "synchronous"), ("robotouille", "asynchronous"), ("alfworld", "valid_unseen"))
#: ALFWorld's tasks are its task types (schemas.labels.ALFWORLD_TASK_TYPES)
ALFWORLD_TYPES = ALFWORLD_TASK_TYPES
SUCCESS = {"recap": 0.65, "react": 0.38, "act": 0.3}
END_FAIL = ("step_cap", "call_cap", "agent_done", "json_failures", "llm_error", "env_error")
PURPOSES = ("descend", "leaf_done", "leaf_fail", "nonleaf_done", "leaf_judge", "repair")
WORDS = np.array(
    "the onion is on table1 cut lettuce stack patty on bottombun cook at stove3 wait pick put "
    "go to counter2 fridge open drawer take apple heat it with microwave clean sink place".split()
)
ACTIONS = np.array(["go to table1", "pick onion", "cut lettuce", "cook patty", "stack", "wait", "put bun"])
TREE_TASKS = np.array(["make a burger", "cut lettuce", "cook patty", "assemble", "serve the dish"])


@dataclass(frozen=True)
class SyntheticSpec:
    """The shape of a synthetic run: about ``messages`` message rows, ``mean_calls`` LLM calls per episode, a
    sliding window of ``window`` messages, and the random ``seed``."""

    messages: int = 1_000_000
    mean_calls: int = 120
    window: int = 64
    seed: int = 0
    #: rows per part file and per row group: the sink writes one part file per batch, so a
    #: real run's files are batch-sized and each covers a limited set of episodes
    part_rows: int = 50_000
    row_group_rows: int = 10_000


def _write(run_dir: Path, table: str, data: pa.Table, writer: str, part_rows: int, row_group_rows: int) -> int:
    """Part files like PartWriter writes them (temporary name, then rename)."""
    schema = arrow_schema(table)
    defaults = column_defaults(table)
    for f in schema:  # columns the generator does not model: their record's default, else null
        if f.name not in data.column_names:
            data = data.append_column(f.name, pa.array([defaults.get(f.name)] * data.num_rows, f.type))
    data = data.select(schema.names).cast(schema)
    folder = run_dir / table
    folder.mkdir(parents=True, exist_ok=True)
    n = 0
    for start in range(0, max(data.num_rows, 1), part_rows):
        n += 1
        final = folder / f"part-{writer}-{n:06d}.parquet"
        tmp = folder / f".tmp-{final.name}"
        pq.write_table(data.slice(start, part_rows), tmp, row_group_size=row_group_rows)
        os.replace(tmp, final)
    return n


def _texts(rng: np.random.Generator, n: int, lo: int, hi: int) -> list[str]:
    """n texts of lo..hi words drawn from a pool (fast: 4,096 distinct bodies + a counter)."""
    pool = [" ".join(rng.choice(WORDS, size=int(k))) for k in rng.integers(lo, hi + 1, size=4096)]
    idx = rng.integers(0, len(pool), size=n)
    return [f"{pool[i]} [{j}]" for j, i in enumerate(idx)]


@dataclass(frozen=True)
class _Episodes:
    """The per-episode plan every table is drawn from: how many calls, messages and steps each
    episode has, its method and place indices, and whether it succeeded."""

    n: int
    ids: np.ndarray
    calls: np.ndarray
    messages: np.ndarray
    steps: np.ndarray
    method: np.ndarray
    split_i: np.ndarray
    task_i: np.ndarray
    layout_seed: np.ndarray
    success: np.ndarray
    end: np.ndarray


@dataclass(frozen=True)
class _CallSums:
    """The calls' totals per episode (successful calls carry tokens), for the episode rows."""

    cost: np.ndarray
    prompt: np.ndarray
    cached: np.ndarray
    completion: np.ndarray


def _starts(counts: np.ndarray) -> np.ndarray:
    """Where each group of ``counts`` rows starts in the flat column."""
    return np.concatenate([[0], np.cumsum(counts)[:-1]])


def _plan_episodes(rng: np.random.Generator, spec: SyntheticSpec) -> _Episodes:
    """Episodes: calls per episode decide messages (2 pinned + prompt and reply per call)."""
    n_ep = max(1, spec.messages // (2 * spec.mean_calls + 2))
    calls_per = np.clip(rng.poisson(spec.mean_calls, n_ep), 2, None).astype(np.int64)
    steps_per = np.maximum(1, (calls_per * rng.uniform(0.4, 0.8, n_ep)).astype(np.int64))
    method = np.array(METHODS)[np.arange(n_ep) % len(METHODS)]
    success = rng.uniform(size=n_ep) < np.vectorize(SUCCESS.get)(method)
    return _Episodes(
        n=n_ep,
        ids=np.array([f"ep-{i:07d}" for i in range(n_ep)]),
        calls=calls_per,
        messages=2 * calls_per + 2,
        steps=steps_per,
        method=method,
        split_i=(np.arange(n_ep) // len(METHODS)) % len(SPLITS),
        task_i=(np.arange(n_ep) // (len(METHODS) * len(SPLITS))) % 10,
        layout_seed=42 * (1 + (np.arange(n_ep) // (len(METHODS) * len(SPLITS) * 10))),
        success=success,
        end=np.where(success, "success", np.array(END_FAIL)[rng.integers(0, len(END_FAIL), n_ep)]),
    )


def _window_seqs(call_idx: np.ndarray, window: int) -> tuple[pa.ListArray, np.ndarray, np.ndarray]:
    """Each call's window (seqs 0, 1 pinned + the newest messages before its reply, at most
    ``window``), with the messages in history when it is made and its window's length."""
    before = 2 + 2 * call_idx + 1  # messages in history when call k is made (its prompt included)
    tail = np.minimum(before - 2, window - 2)
    win_len = 2 + tail
    offsets = np.concatenate([[0], np.cumsum(win_len)]).astype(np.int32)
    values = np.empty(int(win_len.sum()), dtype=np.int64)
    pos = offsets[:-1]
    values[pos] = 0
    values[pos + 1] = 1
    # tail seqs: before - tail .. before - 1
    rel = np.arange(values.size) - np.repeat(pos, win_len)
    mask = rel >= 2
    values[mask] = (np.repeat(before - tail, win_len) + rel - 2)[mask]
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(values)), before, win_len


def _calls_table(rng: np.random.Generator, ep: _Episodes, spec: SyntheticSpec, run_id: str) -> tuple[pa.Table, _CallSums]:
    """The llm_calls rows (prompts grow with the window; ReAct's and Act's with the history too)
    and their totals per episode."""
    n_calls = int(ep.calls.sum())
    call_ep = np.repeat(np.arange(ep.n), ep.calls)
    call_idx = np.arange(n_calls) - np.repeat(_starts(ep.calls), ep.calls)
    window, before, win_len = _window_seqs(call_idx, spec.window)
    prompt = (
        300
        + 55 * (win_len - 2)
        + rng.integers(0, 200, n_calls)
        + np.where(np.repeat(ep.method, ep.calls) == "recap", 0, 20 * np.minimum(call_idx, 40))
    ).astype(np.int64)
    cached = (prompt * rng.uniform(0, 0.6, n_calls)).astype(np.int64)
    completion = rng.integers(20, 200, n_calls).astype(np.int64)
    status = np.where(rng.uniform(size=n_calls) < 0.01, "error", "ok")
    ok = status == "ok"
    cost = np.where(ok, (prompt - cached) * 2.5e-6 + cached * 1.25e-6 + completion * 1e-5, 0.0)
    retries = np.where(status == "error", rng.integers(1, 4, n_calls), (rng.uniform(size=n_calls) < 0.02).astype(np.int64))
    purpose = np.where(call_idx == 0, "task", np.array(PURPOSES)[rng.integers(0, len(PURPOSES), n_calls)])
    calls = pa.table(
        {
            "run_id": pa.array([run_id] * n_calls),
            "episode_id": ep.ids[call_ep],
            "call_index": call_idx,
            "call_key": np.char.add(np.char.add(ep.ids[call_ep], "#"), call_idx.astype(str)),
            "purpose": purpose,
            "window_seqs": window,
            "model": np.where(ok, "gpt-4o", ""),
            "status": status,
            "node_id": pa.nulls(n_calls, pa.int64()),
            "response_seq": before,
            "error_kind": pa.array(["rate_limit" if s == "error" else None for s in status.tolist()], pa.string()),
            "error_message": pa.nulls(n_calls, pa.string()),
            "prompt_tokens": np.where(ok, prompt, 0),
            "cached_prompt_tokens": np.where(ok, cached, 0),
            "completion_tokens": np.where(ok, completion, 0),
            "cost_usd": cost,
            "latency_s": rng.uniform(0.3, 3.0, n_calls),
            "retries": retries,
            "token_count_source": ["provider"] * n_calls,
            "served_from": ["provider"] * n_calls,
            "deployment": pa.nulls(n_calls, pa.string()),
            "test_double": np.zeros(n_calls, dtype=bool),
        }
    )

    def per_episode(values: np.ndarray) -> np.ndarray:
        return np.bincount(call_ep, weights=np.where(ok, values, 0), minlength=ep.n).astype(np.int64)

    sums = _CallSums(
        cost=np.bincount(call_ep, weights=cost, minlength=ep.n),
        prompt=per_episode(prompt),
        cached=per_episode(cached),
        completion=per_episode(completion),
    )
    return calls, sums


def _messages_table(rng: np.random.Generator, ep: _Episodes, run_id: str) -> pa.Table:
    """The messages rows: two pinned ones (demonstration, task), then observation and reply in turn."""
    n_msg = int(ep.messages.sum())
    msg_ep = np.repeat(np.arange(ep.n), ep.messages)
    msg_seq = np.arange(n_msg) - np.repeat(_starts(ep.messages), ep.messages)
    role = np.where((msg_seq >= 2) & (msg_seq % 2 == 1), "assistant", "user")
    kind = np.where(
        msg_seq == 0, "demonstration", np.where(msg_seq == 1, "task", np.where(role == "assistant", "reply", "observation"))
    )
    return pa.table(
        {
            "run_id": pa.array([run_id] * n_msg),
            "episode_id": ep.ids[msg_ep],
            "seq": msg_seq,
            "role": role,
            "kind": kind,
            "content": _texts(rng, n_msg, 20, 90),
            "node_id": pa.nulls(n_msg, pa.int64()),
            "pinned": msg_seq < 2,
        }
    )


def _steps_table(rng: np.random.Generator, ep: _Episodes, run_id: str) -> pa.Table:
    """The steps rows: a few invalid attempts, some episodes end in an a-b loop."""
    n_steps = int(ep.steps.sum())
    st_ep = np.repeat(np.arange(ep.n), ep.steps)
    st_idx = np.arange(n_steps) - np.repeat(_starts(ep.steps), ep.steps)
    valid = rng.uniform(size=n_steps) > 0.08
    act = ACTIONS[rng.integers(0, len(ACTIONS), n_steps)]
    obs = np.char.add("state ", st_idx.astype(str))
    last = np.repeat(ep.steps, ep.steps) - 1  # each row's episode's last step index
    looping = np.repeat(rng.uniform(size=ep.n) < 0.1, ep.steps) & (st_idx > last - 8)  # its last 8 steps
    act = np.where(looping, np.where(st_idx % 2 == 0, "go to table1", "go to table2"), act)
    obs = np.where(looping, np.where(st_idx % 2 == 0, "at table1", "at table2"), obs)
    return pa.table(
        {
            "run_id": pa.array([run_id] * n_steps),
            "episode_id": ep.ids[st_ep],
            "index": st_idx,
            "env_step": st_idx + 1,
            "action": act,
            "valid": valid | looping,
            "observation": obs,
            "done": st_idx == last,
            "success": (st_idx == last) & np.repeat(ep.success, ep.steps),
            "node_id": pa.nulls(n_steps, pa.int64()),
        }
    )


def _versions(rng: np.random.Generator, kind: np.ndarray) -> pa.ListArray:
    """Each node's versions (primitives have one, the others 1 to 4), each with a think text and subtasks."""
    n_nodes = len(kind)
    n_ver = np.where(kind == "primitive", 1, rng.integers(1, 5, n_nodes))
    v_total = int(n_ver.sum())
    v_off = np.concatenate([[0], np.cumsum(n_ver)]).astype(np.int32)
    v_num = (np.arange(v_total) - np.repeat(v_off[:-1], n_ver)).astype(np.int32)
    sub_len = rng.integers(1, 6, v_total)
    s_off = np.concatenate([[0], np.cumsum(sub_len)]).astype(np.int32)
    subtasks = pa.ListArray.from_arrays(pa.array(s_off), pa.array(ACTIONS[rng.integers(0, len(ACTIONS), int(sub_len.sum()))]))
    return pa.ListArray.from_arrays(
        pa.array(v_off),
        pa.StructArray.from_arrays(
            [
                pa.array(v_num),
                pa.array(_texts(rng, v_total, 5, 25), pa.string()),
                subtasks,
                pa.array(rng.integers(0, 100, v_total).astype(np.int32)),
                pa.array(rng.integers(2, 200, v_total)),
            ],
            names=["version", "think", "subtasks", "call_index", "message_seq"],
        ),
    )


def _tree_nodes_table(rng: np.random.Generator, ep: _Episodes, run_id: str) -> tuple[pa.Table, np.ndarray]:
    """Task trees for the ReCAP episodes (root, up to 8 composites, leaves under them), and every
    episode's tree depth (2 for ReCAP, 0 for the others)."""
    rec = np.flatnonzero(ep.method == "recap")
    nodes_per = np.maximum(3, ep.steps[rec] + 1 + np.minimum(8, ep.steps[rec] // 4))
    n_nodes = int(nodes_per.sum())
    nd_id = np.arange(n_nodes) - np.repeat(_starts(nodes_per), nodes_per)
    n_comp = np.repeat(np.minimum(8, ep.steps[rec] // 4) + 1, nodes_per)  # node 1..n_comp-1 composite
    is_comp = (nd_id >= 1) & (nd_id < n_comp)
    leaf_slot = nd_id - n_comp
    parent = np.where(nd_id == 0, -1, np.where(is_comp, 0, np.where(n_comp > 1, leaf_slot % np.maximum(n_comp - 1, 1) + 1, 0)))
    child_index = np.where(
        nd_id == 0, 0, np.where(is_comp, nd_id - 1, np.where(n_comp > 1, leaf_slot // np.maximum(n_comp - 1, 1), leaf_slot))
    )
    kind = np.where(nd_id == 0, "root", np.where(is_comp, "composite", "primitive"))
    status = np.where(rng.uniform(size=n_nodes) < 0.05, "failed", "done")
    nodes = pa.table(
        {
            "run_id": pa.array([run_id] * n_nodes),
            "episode_id": ep.ids[np.repeat(rec, nodes_per)],
            "node_id": nd_id,
            "parent_id": pa.array(parent, mask=parent < 0),
            "depth": np.where(nd_id == 0, 0, np.where(is_comp | (parent == 0), 1, 2)),
            "child_index": child_index,
            "task": TREE_TASKS[nd_id % len(TREE_TASKS)],
            "kind": kind,
            "status": status,
            "versions": _versions(rng, kind),
            "step_index": pa.nulls(n_nodes, pa.int64()),
        }
    )
    max_depth = np.zeros(ep.n, dtype=np.int64)
    max_depth[rec] = 2
    return nodes, max_depth


def _places(ep: _Episodes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Each episode's benchmark, split, task and instance id, as the pipeline writes them
    (schemas.labels.place_of): Robotouille's task is its environment's name and its instance id
    names split, task and layout seed; ALFWorld is one split whose tasks are the six task types, one game
    per instance id."""
    bench = np.array([b for b, _ in SPLITS])[ep.split_i]
    split = np.array([s for _, s in SPLITS])[ep.split_i]
    robot_task = np.char.add(ep.task_i.astype(str), "_recipe")
    alf = bench == "alfworld"
    task = np.where(alf, np.array(ALFWORLD_TYPES)[ep.task_i % len(ALFWORLD_TYPES)], robot_task)
    instance = np.where(
        alf,
        np.char.add(np.char.add(np.char.add("alfworld/", task), "/game-"), ep.task_i.astype(str)),
        np.char.add(
            np.char.add(np.char.add(np.char.add(np.char.add("robotouille/", split), "/"), robot_task), "@"),
            ep.layout_seed.astype(str),
        ),
    )
    return bench, split, task, instance


def _episodes_table(
    rng: np.random.Generator, ep: _Episodes, sums: _CallSums, max_depth: np.ndarray, spec: SyntheticSpec, run_id: str
) -> pa.Table:
    """The episodes rows, their totals those of their calls."""
    bench, split, task, instance = _places(ep)
    # canonical configs, as the driver stores them (recap.config / recap.baselines to_json)
    cfg = np.where(ep.method == "recap", ReCAPConfig(window=spec.window).to_json(), ReActConfig(window=spec.window).to_json())
    unit = np.char.add(np.char.add(np.char.add(ep.method, "|"), instance), np.char.add("|", ep.layout_seed.astype(str)))
    ended = 1.7e9 + np.arange(ep.n, dtype=np.float64)
    n_ep = ep.n
    return pa.table(
        {
            "run_id": pa.array([run_id] * n_ep),
            "episode_id": ep.ids,
            "unit_id": unit,
            "attempt": np.ones(n_ep, dtype=np.int64),
            "benchmark": bench,
            "split": split,
            "task": task,
            "instance_id": instance,
            # each unit one sampling seed, numbered like its instance's layout seed
            "sampling_seed": ep.layout_seed,
            "method": ep.method,
            "method_config": cfg,
            "model": ["gpt-4o"] * n_ep,
            "end_reason": ep.end,
            "success": ep.success,
            "steps": ep.steps,
            "llm_calls": ep.calls,
            "prompt_tokens": sums.prompt,
            "cached_prompt_tokens": sums.cached,
            "completion_tokens": sums.completion,
            "cost_usd": sums.cost,
            "wall_s": rng.uniform(30, 600, n_ep),
            "step_cap": np.full(n_ep, 120, dtype=np.int64),
            "step_multiplier": np.full(n_ep, 4.0),
            "optimal_steps": np.full(n_ep, 30, dtype=np.int64),
            "max_depth": max_depth,
            "error": pa.nulls(n_ep, pa.string()),
            "worker_id": ["w0"] * n_ep,
            "started_at": ended - 100.0,
            "ended_at": ended,
            "test_double": np.zeros(n_ep, dtype=bool),
            "label": ep.method,
            "profile": pa.nulls(n_ep, pa.string()),
            "ablation": pa.nulls(n_ep, pa.string()),
            "provider_model": ["openai/gpt-4o-2024-08-06"] * n_ep,
        }
    )


def _run_table(run_id: str) -> pa.Table:
    """The one run row."""
    return pa.table(
        {
            "run_id": [run_id],
            "started_at": [1.7e9],
            "spec_yaml": ["synthetic: true\n"],
            "spec_hash": ["synthetic"],
            "package_versions": ["{}"],
            "git_revision": [None],
            "host": ["bench"],
            "command": ["python -m reports.synthetic"],
            "schema_version": [SCHEMA_VERSION],
        }
    )


def write_synthetic_run(run_dir: str | Path, spec: SyntheticSpec = SyntheticSpec(), run_id: str = "synthetic") -> dict[str, int]:
    """Write a run folder with about ``spec.messages`` message rows; returns rows per table."""
    rng = np.random.default_rng(spec.seed)
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text(json.dumps({"run_id": run_id, "spec_hash": "synthetic"}))
    # one generator for every table: the order of the draws below is part of the output
    ep = _plan_episodes(rng, spec)
    calls, sums = _calls_table(rng, ep, spec, run_id)
    messages = _messages_table(rng, ep, run_id)
    steps = _steps_table(rng, ep, run_id)
    nodes, max_depth = _tree_nodes_table(rng, ep, run_id)
    episodes = _episodes_table(rng, ep, sums, max_depth, spec, run_id)
    counts = {}
    for table, data in (
        ("episodes", episodes),
        ("llm_calls", calls),
        ("messages", messages),
        ("steps", steps),
        ("tree_nodes", nodes),
        ("run", _run_table(run_id)),
    ):
        _write(run_dir, table, data, "synth001", spec.part_rows, spec.row_group_rows)
        counts[table] = data.num_rows
    return counts


def main(argv: list[str] | None = None) -> int:
    """``python -m reports.synthetic OUT_DIR``: write a synthetic run folder and print its rows per table."""
    p = argparse.ArgumentParser(prog="python -m reports.synthetic", description="Write a synthetic run folder.")
    p.add_argument("out_dir")
    p.add_argument("--messages", type=int, default=SyntheticSpec.messages)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    counts = write_synthetic_run(a.out_dir, SyntheticSpec(messages=a.messages, seed=a.seed))
    print(", ".join(f"{k}: {v:,}" for k, v in counts.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
