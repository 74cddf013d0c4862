"""The episode pages' SQL: one page of the episode list, one episode's rows, and the window of one call."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from reports.webview.errors import BadRequest
from reports.webview.listquery import ListQuery
from reports.webview.snapshot import FILTERS, Snapshot


@dataclass
class EpisodePage:
    """One page of the episode list, the total matching rows across pages, and how long the query took (ms)."""

    rows: list[dict[str, Any]]
    total: int
    query: ListQuery
    elapsed_ms: float


_LIST_COLUMNS = (
    "run_id",
    "episode_id",
    "unit_id",
    "attempt",
    "is_latest",
    "model_label",
    "arm",
    "method",
    "ablation",
    "benchmark",
    "split",
    "env_split",
    "task",
    "instance_id",
    "sampling_seed",
    "end_reason",
    "success",
    "mode",
    "steps",
    "llm_calls",
    "cost_usd",
    "wall_s",
)


def episode_list(snap: Snapshot, lq: ListQuery) -> EpisodePage:
    """The page of episode rows ``lq`` asks for (filters, search hits, sort, page); ties are broken by episode
    and run id so pages never overlap."""
    t0 = time.perf_counter()
    where, params = [], {}
    for i, (param, value) in enumerate(lq.filters.items()):
        col = dict(FILTERS)[param]
        if param == "success":
            where.append(f'"{col}" = {"true" if value == "true" else "false"}')
        else:
            where.append(f'CAST("{col}" AS VARCHAR) = $f{i}')
            params[f"f{i}"] = value
    if lq.latest:
        where.append("is_latest")
    hits = ""
    if lq.q:
        hits = f"JOIN temp.{snap.hits_table(lq.q.lower())} h ON h.run_id = e.run_id AND h.episode_id = e.episode_id"
    cols = [c for c in _LIST_COLUMNS if c in snap.columns] + [c for c in ("label", "profile") if c in snap.columns]
    select = ", ".join(f'e."{c}"' for c in cols) + (", h.hits, h.first_hit" if lq.q else ", NULL AS hits, NULL AS first_hit")
    order = f'e."{lq.sort}" {"DESC" if lq.desc else "ASC"} NULLS LAST, e.episode_id, e.run_id'
    sql = (
        f"SELECT {select}, count(*) OVER () AS total FROM _episode_list e {hits} "
        f"{'WHERE ' + ' AND '.join(where) if where else ''} ORDER BY {order} "
        f"LIMIT {lq.per} OFFSET {(lq.page - 1) * lq.per}"
    )
    res = snap.query(sql, params)
    rows = res.dicts()
    total = rows[0]["total"] if rows else (0 if lq.page == 1 else _count(snap, where, hits, params))
    return EpisodePage(rows, total, lq, (time.perf_counter() - t0) * 1000)


def _count(snap: Snapshot, where: list[str], hits: str, params: dict[str, Any]) -> int:
    sql = f"SELECT count(*) FROM _episode_list e {hits} {'WHERE ' + ' AND '.join(where) if where else ''}"
    return int(snap.query(sql, params).rows[0][0])


# -- one episode -------------------------------------------------------------------------------------


@dataclass
class Episode:
    """One episode as the viewer shows it: its row and the rows of its tree nodes, steps, calls, messages (each with
    its ``tool_call_id`` and ``tool_calls``, None when it has none) and tool calls, and the query time (ms)."""

    meta: dict[str, Any]
    nodes: list[dict[str, Any]]
    steps: list[dict[str, Any]]
    calls: list[dict[str, Any]]
    messages: list[dict[str, Any]]
    elapsed_ms: float
    #: the ``tool_calls`` rows, in the order they were made ([] for a run without any)
    tool_calls: list[dict[str, Any]] = field(default_factory=list)
    #: the ``evaluations`` row of a judged coding episode ([] for any other)
    evaluations: list[dict[str, Any]] = field(default_factory=list)


def find_episode(snap: Snapshot, episode_id: str, run_id: str | None) -> tuple[str, str]:
    """(run_id, episode_id) of an episode named by id (and run when several runs hold it)."""
    if not episode_id or len(episode_id) > 300:
        raise BadRequest("give an episode id (id=...)")
    rows = snap.query("SELECT DISTINCT run_id FROM _episode_list WHERE episode_id = $e ORDER BY 1", {"e": episode_id}).rows
    runs_ = [r[0] for r in rows]
    if run_id:
        if run_id not in runs_:
            raise BadRequest(f"no episode {episode_id!r} in run {run_id!r}", 404)
        return run_id, episode_id
    if not runs_:
        raise BadRequest(f"no episode {episode_id!r} in these runs", 404)
    if len(runs_) > 1:
        raise BadRequest(f"episode {episode_id!r} is in several runs ({', '.join(runs_)}): add run=...", 409)
    return runs_[0], episode_id


def episode(snap: Snapshot, run_id: str, episode_id: str) -> Episode:
    """Everything about one episode, through the report viewer's queries (reports/sql/viewer_*)."""
    t0 = time.perf_counter()
    ids = {"ids": [episode_id]}

    def mine(name: str) -> list[dict[str, Any]]:
        return [r for r in snap.named(name, ids).dicts() if r["run_id"] == run_id]

    meta = mine("viewer_episodes")
    if not meta:
        raise BadRequest(f"no episode {episode_id!r} in run {run_id!r}", 404)
    extra = snap.query(
        "SELECT * FROM _episode_list WHERE run_id = $r AND episode_id = $e", {"r": run_id, "e": episode_id}
    ).dicts()
    m = {**(extra[0] if extra else {}), **meta[0]}
    out = Episode(
        m,
        mine("viewer_nodes"),
        mine("viewer_steps"),
        mine("viewer_calls"),
        with_tool_fields(mine("viewer_messages"), mine("viewer_message_tools")),
        0.0,
        mine("viewer_tool_calls"),
        mine("viewer_evaluations"),
    )
    out.elapsed_ms = (time.perf_counter() - t0) * 1000
    return out


def with_tool_fields(messages: list[dict[str, Any]], tools: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``messages`` with each one's ``tool_call_id`` and ``tool_calls`` (None where ``tools``, the rows of
    viewer_message_tools, has none). Kept as a query of its own so the report's viewer_messages stays as it was."""
    by_seq = {t["seq"]: t for t in tools}
    return [
        {
            **m,
            "tool_call_id": by_seq.get(m["seq"], {}).get("tool_call_id"),
            "tool_calls": by_seq.get(m["seq"], {}).get("tool_calls"),
        }
        for m in messages
    ]


def call_window(snap: Snapshot, run_id: str, episode_id: str, call_index: int) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """One call and the exact messages it was sent, in window order, rebuilt from ``window_seqs``."""
    call = snap.query(
        "SELECT call_index, purpose, status, window_seqs, response_seq, model_label, prompt_tokens, completion_tokens, "
        "cost_usd, latency_s, retries, error_kind, error_message FROM calls "
        "WHERE run_id = $r AND episode_id = $e AND call_index = $c",
        {"r": run_id, "e": episode_id, "c": call_index},
    ).dicts()
    if not call:
        raise BadRequest(f"episode {episode_id!r} has no call {call_index}", 404)
    msgs = snap.query(
        "WITH w AS (SELECT unnest(window_seqs) AS seq, generate_subscripts(window_seqs, 1) AS pos FROM llm_calls "
        "WHERE run_id = $r AND episode_id = $e AND call_index = $c) "
        "SELECT w.pos, w.seq, m.role, m.kind, m.pinned, m.node_id, m.content, m.tool_call_id, m.tool_calls FROM w "
        "LEFT JOIN messages m ON m.run_id = $r AND m.episode_id = $e AND m.seq = w.seq ORDER BY w.pos",
        {"r": run_id, "e": episode_id, "c": call_index},
    ).dicts()
    return call[0], msgs
