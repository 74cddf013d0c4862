"""What the viewer reads: a snapshot of the run folders' tables, rebuilt when part files change.

A :class:`Snapshot` is one read-only DuckDB connection from :func:`reports.views.open_runs_checked`
(the part files reach DuckDB as Arrow datasets; DuckDB's file access is off and its configuration
locked), with the report's views (``attempts``, ``episode_modes``, ``calls``, ...) and two things
held in memory so that every list and filter stays far under 300 ms on a million messages:

* ``_episode_list``: one row per episode row (every attempt), the labels of ``attempts`` and the
  ``mode`` of ``episode_modes`` (about 10,000 rows);
* ``_search``: the lower-cased text of every message with its (run, episode, seq), kept per part
  file in :class:`SearchIndex` so that a new part costs only its own rows. Scanning that column
  in memory takes about 100 ms per million messages; decoding it from Parquet on every search
  would take several times that. Nothing is written anywhere: the run folders stay untouched.

:class:`Catalog` watches the table folders (names, sizes and times of the part files) and builds
a new snapshot in a background thread when they change, so a page shows rows that a running
sweep wrote a moment ago without waiting for the rebuild. Queries on one snapshot are serialised
(one DuckDB connection is not shared between threads).
"""

from __future__ import annotations

import logging
import os
import re
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import duckdb
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from reports.sections import PLAN_FILE, load_plans
from reports.stats import SignFlipTest, clustered_mcnemar_exact, clustered_permutation_test, instance_discordance
from reports.views import ReportError, Result, materialize, named_query, open_runs_checked, run_query, scan_runs
from schemas.parts import RUN_FILE, read_run_file
from schemas.tables import TABLES

log = logging.getLogger(__name__)

#: filters of the episode list: (parameter, column of _episode_list); optional ones only when present
FILTERS: tuple[tuple[str, str], ...] = (
    ("run", "run_id"),
    ("model", "model_label"),
    ("label", "label"),
    ("arm", "arm"),
    ("method", "method"),
    ("profile", "profile"),
    ("ablation", "ablation"),
    ("benchmark", "benchmark"),
    ("split", "split"),
    ("task", "task"),
    ("end_reason", "end_reason"),
    ("mode", "mode"),
    ("success", "success"),
)
#: columns the list may be sorted by (the URL names them; nothing else reaches the SQL)
SORTABLE = (
    "episode_id",
    "run_id",
    "model_label",
    "arm",
    "label",
    "env_split",
    "task",
    "instance_id",
    "seed",
    "attempt",
    "end_reason",
    "mode",
    "success",
    "steps",
    "llm_calls",
    "cost_usd",
    "wall_s",
    "ended_at",
)
PAGE_SIZES = (25, 50, 100, 200)
#: the longest search text accepted (a phrase, not a document)
MAX_QUERY_CHARS = 200
#: searches whose hits a snapshot keeps (paging or re-sorting a search does not scan again)
SEARCH_CACHE = 16


class BadRequest(ReportError):
    """A request the viewer refuses (unknown filter value, page, episode ...): a 4xx, one line."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status


# -- the search index ------------------------------------------------------------------------------


class SearchIndex:
    """Lower-cased message text per messages part file; a part is read once (parts never change
    after their atomic rename, so the path, size and mtime identify its contents)."""

    def __init__(self) -> None:
        self._parts: dict[tuple[str, int, int], pa.Table] = {}

    def table(self, files: Sequence[Path]) -> pa.Table:
        """The search column (run_id, episode_id, seq, lower-cased text) over ``files``: parts already read are
        reused, new ones read, and parts no longer listed forgotten."""
        keep: dict[tuple[str, int, int], pa.Table] = {}
        for f in files:
            try:
                st = f.stat()
            except OSError:
                continue
            key = (str(f), st.st_size, st.st_mtime_ns)
            part = self._parts.get(key)
            if part is None:
                raw = pq.read_table(f, columns=["run_id", "episode_id", "seq", "content"])
                part = pa.table(
                    {
                        "run_id": raw["run_id"],
                        "episode_id": raw["episode_id"],
                        "seq": raw["seq"],
                        "text": pc.utf8_lower(raw["content"]),
                    }
                )
            keep[key] = part
        self._parts = keep
        if not keep:
            return pa.table(
                {
                    "run_id": pa.array([], pa.string()),
                    "episode_id": pa.array([], pa.string()),
                    "seq": pa.array([], pa.int64()),
                    "text": pa.array([], pa.string()),
                }
            )
        return pa.concat_tables(list(keep.values()))


# -- one snapshot ----------------------------------------------------------------------------------


_LIST_SQL = """
CREATE TEMP TABLE _episode_list AS
SELECT a.*, m.mode
FROM attempts a
LEFT JOIN episode_modes m ON m.run_id = a.run_id AND m.episode_id = a.episode_id
"""


@dataclass
class Snapshot:
    """A locked-down connection over the run folders as they were at ``built_at``."""

    con: duckdb.DuckDBPyConnection
    run_dirs: list[Path]
    columns: set[str]
    options: dict[str, list[Any]]
    skipped: list[Any]
    built_at: float
    lock: threading.Lock = field(default_factory=threading.Lock)
    #: search text -> temp table of its hits (run_id, episode_id, hits, first_hit), newest last
    hits: dict[str, str] = field(default_factory=dict)

    def hits_table(self, text: str) -> str:
        """The temp table of the episodes whose messages hold ``text`` (lower case): one scan of
        the search column per distinct text, kept for the next pages, sorts and filters."""
        with self.lock:
            name = self.hits.pop(text, None)
            if name is None:
                name = f"_hits_{len(self.hits)}_{int(time.time() * 1e6)}"
                self.con.execute(
                    f"CREATE TEMP TABLE {name} AS SELECT run_id, episode_id, count(*) AS hits, min(seq) AS first_hit "
                    "FROM _search WHERE contains(text, $q) GROUP BY ALL",
                    {"q": text},
                )
                while len(self.hits) >= SEARCH_CACHE:
                    old = self.hits.pop(next(iter(self.hits)))
                    self.con.execute(f"DROP TABLE IF EXISTS {old}")
            self.hits[text] = name
            return name

    def query(self, sql: str, params: dict[str, Any] | None = None) -> Result:
        """Run a read-only query on this snapshot (serialised: the connection is not shared between threads)."""
        with self.lock:
            return run_query(self.con, sql, params)

    def named(self, name: str, params: dict[str, Any] | None = None) -> Result:
        """Run a stored query (``reports/sql/<name>.sql``) on this snapshot, serialised like :meth:`query`."""
        with self.lock:
            return named_query(self.con, name, params)

    def close(self) -> None:
        """Close the connection once no query holds the lock (the snapshot was replaced)."""
        with self.lock:
            self.con.close()


def build_snapshot(run_dirs: Sequence[Path], index: SearchIndex) -> Snapshot:
    """A fresh snapshot of ``run_dirs``: the views, the in-memory episode list and search column, and the values
    each filter can take. Reads only."""
    dirs, files, _ = scan_runs(run_dirs)
    con, skipped = open_runs_checked(dirs)
    try:
        materialize(con, ("attempts", "episode_modes"))
        con.execute(_LIST_SQL)
        search = index.table(files["messages"])  # noqa: F841 - registered below
        con.register("_search", search)
        load_plans(con)
        columns = {r[0] for r in con.execute("SELECT column_name FROM (DESCRIBE SELECT * FROM _episode_list)").fetchall()}
        options: dict[str, list[Any]] = {}
        for param, col in FILTERS:
            if col in columns:
                options[param] = [
                    r[0]
                    for r in con.execute(
                        f'SELECT DISTINCT "{col}" FROM _episode_list WHERE "{col}" IS NOT NULL ORDER BY 1'
                    ).fetchall()
                ]
    except BaseException:
        con.close()
        raise
    return Snapshot(con, dirs, columns, options, skipped, time.time())


def _fingerprint(run_dirs: Sequence[Path]) -> tuple:
    """Names, sizes and times of every part file and run file: changes when a part lands."""
    out: list[tuple[str, int, int]] = []
    for d in run_dirs:
        for table in TABLES:
            folder = d / table
            try:
                with os.scandir(folder) as it:
                    out.extend(
                        (e.path, e.stat().st_size, e.stat().st_mtime_ns)
                        for e in it
                        if e.name.endswith(".parquet") and not e.name.startswith(".")
                    )
            except OSError:
                continue
        for name in (RUN_FILE, PLAN_FILE):
            try:
                st = (d / name).stat()
                out.append((str(d / name), st.st_size, st.st_mtime_ns))
            except OSError:
                pass
    return tuple(sorted(out))


class Catalog:
    """The current snapshot of ``run_dirs`` and a background refresher (``poll_s`` > 0)."""

    def __init__(self, run_dirs: Sequence[str | Path], *, poll_s: float = 2.0) -> None:
        self.run_dirs, _, _ = scan_runs(run_dirs)  # validates the folders (RunDirError)
        self._index = SearchIndex()
        self._print = _fingerprint(self.run_dirs)
        self._snap = build_snapshot(self.run_dirs, self._index)
        self._swap = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        if poll_s > 0:
            self._thread = threading.Thread(target=self._poll, args=(poll_s,), name="recap-view-refresh", daemon=True)
            self._thread.start()

    @property
    def snap(self) -> Snapshot:
        """The snapshot to query now; the refresher swaps it whole, so a caller keeps a consistent one."""
        return self._snap

    def refresh(self) -> bool:
        """Rebuild when the part files changed; True when a new snapshot is in place."""
        with self._swap:
            fp = _fingerprint(self.run_dirs)
            if fp == self._print:
                return False
            new = build_snapshot(self.run_dirs, self._index)
            old, self._snap, self._print = self._snap, new, fp
        old.close()
        return True

    def _poll(self, every: float) -> None:
        while not self._stop.wait(every):
            try:
                self.refresh()
            except Exception as exc:  # noqa: BLE001 - a half-written folder: keep the last snapshot
                log.warning("recap view: refresh failed, keeping the last snapshot: %s", exc)

    def close(self) -> None:
        """Stop the refresher (waiting up to 5 s) and close the current snapshot."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._snap.close()


# -- runs -----------------------------------------------------------------------------------------

_SECRET_KEY = re.compile(r"(key|token|secret|password|passwd|authorization|credential)", re.I)
_SECRET_VALUE = re.compile(
    r"\b(sk-[A-Za-z0-9_\-]{8,}|(?:AKIA|ASIA)[A-Z0-9]{12,}|[A-Za-z0-9_\-]{20,}\.[A-Za-z0-9_\-]{20,}\.[A-Za-z0-9_\-]{10,})\b"
)


def redact_spec(text: str) -> str:
    """The sweep file with any value under a key that names a secret replaced (``api_key_env``
    names a variable, not a key, and stays) and key-shaped strings masked anywhere."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^(\s*-?\s*)([A-Za-z0-9_\-]+)(\s*:\s*)(.+)$", line)
        if m and _SECRET_KEY.search(m.group(2)) and m.group(2) != "api_key_env" and m.group(4).strip() not in ("", "null", "~"):
            line = f"{m.group(1)}{m.group(2)}{m.group(3)}<redacted>"
        out.append(_SECRET_VALUE.sub("<redacted>", line))
    return "\n".join(out) + ("\n" if text.endswith("\n") else "")


def _spec_caps(spec_yaml: str | None) -> dict[str, Any]:
    import yaml

    try:
        data = yaml.safe_load(spec_yaml or "") or {}
    except yaml.YAMLError:
        return {}
    if not isinstance(data, dict):
        return {}
    caps: dict[str, Any] = {}
    if data.get("run_cap_usd") is not None:
        caps["run_cap_usd"] = data["run_cap_usd"]
    limits = data.get("limits")
    if isinstance(limits, dict):
        caps.update({f"episode_{k}": v for k, v in limits.items()})
    for m in data.get("models") or []:
        if isinstance(m, dict) and m.get("cap_usd") is not None:
            caps[f"cap_usd[{m.get('label') or m.get('model')}]"] = m["cap_usd"]
    return caps


def runs(snap: Snapshot) -> list[dict[str, Any]]:
    """One row per run: name, folder, started, units planned / done, success, spend, caps."""
    base = {r["run_id"]: r for r in snap.named("runs").dicts()}
    cover_by: dict[str, dict[str, int]] = {}
    for r in snap.named("coverage").dicts():  # per run and arm: summed per run here
        c = cover_by.setdefault(r["run_id"], {})
        for k in _COVERAGE_COUNTS:
            if k in r:
                c[k] = c.get(k, 0) + int(r[k] or 0)
    spend = {
        r["run_id"]: r
        for r in snap.query("SELECT run_id, sum(cost_usd) AS spend_usd, count(*) AS calls FROM llm_calls GROUP BY run_id").dicts()
    }
    specs = {
        r["run_id"]: r["spec_yaml"]
        for r in snap.query("SELECT run_id, arg_max(spec_yaml, started_at) AS spec_yaml FROM run GROUP BY run_id").dicts()
    }
    folders = snap.query("SELECT run_dir, run_json_id FROM run_dirs ORDER BY run_dir").dicts()
    out = []
    seen = set()
    for f in folders:
        rid = f["run_json_id"]
        name = _run_name(Path(f["run_dir"]))
        ids = [rid] if rid else sorted(k for k in base if k not in seen)
        for run_id in ids:
            seen.add(run_id)
            b, c, s = base.get(run_id, {}), cover_by.get(run_id, {}), spend.get(run_id, {})
            out.append(
                {
                    "run_id": run_id,
                    "name": name,
                    "run_dir": f["run_dir"],
                    "started": b.get("first_started"),
                    "starts": b.get("starts", 0),
                    "host": b.get("host"),
                    "git_revision": b.get("git_revision"),
                    "planned": c.get("planned"),
                    "finished": c.get("finished"),
                    "successes": c.get("successes"),
                    "capped": c.get("capped"),
                    "not_started": c.get("not_started"),
                    "gave_up": c.get("gave_up", c.get("infra_failed")),
                    "units": b.get("units", 0),
                    "spend_usd": s.get("spend_usd") or 0.0,
                    "calls": s.get("calls", 0),
                    "caps": _spec_caps(specs.get(run_id)),
                    "has_spec": specs.get(run_id) is not None,
                }
            )
    return out


#: the unit counts of reports/sql/coverage.sql (gave_up was infra_failed before schema version 2)
_COVERAGE_COUNTS = ("planned", "finished", "successes", "capped", "gave_up", "infra_failed", "not_started")


def run_spec(snap: Snapshot, run_id: str) -> str:
    """The sweep file the run was started with (its latest session), secrets redacted; a 404 when none was recorded."""
    r = snap.query("SELECT arg_max(spec_yaml, started_at) AS s FROM run WHERE run_id = $r", {"r": run_id}).rows
    if not r or r[0][0] is None:
        raise BadRequest(f"no sweep file recorded for run {run_id!r}", 404)
    return redact_spec(r[0][0])


def _run_name(run_dir: Path) -> str:
    data = read_run_file(run_dir) or {}
    return str(data.get("run") or data.get("name") or run_dir.name)


# -- the episode list -------------------------------------------------------------------------------


@dataclass(frozen=True)
class ListQuery:
    """The episode list's checked URL parameters: column filters, a message search ``q``, sort column and
    direction, page (1-based) and page size, and whether only the counted (latest) row of each unit is shown."""

    filters: dict[str, str]
    q: str = ""
    sort: str = "episode_id"
    desc: bool = False
    page: int = 1
    per: int = 50
    latest: bool = False


def parse_list_query(params: dict[str, list[str]], snap: Snapshot) -> ListQuery:
    """The list's URL parameters, checked: unknown names, values or pages are a 400."""
    known = {p for p, _ in FILTERS} | {"q", "sort", "dir", "page", "per", "latest"}
    unknown = sorted(set(params) - known)
    if unknown:
        raise BadRequest(f"unknown parameter(s): {', '.join(unknown)}")
    one = {k: v[-1] for k, v in params.items()}
    filters: dict[str, str] = {}
    for param, col in FILTERS:
        value = one.get(param, "")
        if value == "":
            continue
        if col not in snap.columns:
            raise BadRequest(f"filter {param!r} is not available for these runs")
        if param == "success":
            if value not in ("true", "false"):
                raise BadRequest("success must be true or false")
        elif value not in {str(v) for v in snap.options.get(param, [])}:
            raise BadRequest(f"no episode has {param} = {value!r}")
        filters[param] = value
    q = " ".join(one.get("q", "").split())
    if len(q) > MAX_QUERY_CHARS:
        raise BadRequest(f"search text longer than {MAX_QUERY_CHARS} characters")
    sort = one.get("sort", "episode_id") or "episode_id"
    if sort not in SORTABLE or (sort not in snap.columns):
        raise BadRequest(f"cannot sort by {sort!r}")
    direction = one.get("dir", "asc") or "asc"
    if direction not in ("asc", "desc"):
        raise BadRequest("dir must be asc or desc")
    try:
        page = int(one.get("page", "1") or "1")
        per = int(one.get("per", "50") or "50")
    except ValueError:
        raise BadRequest("page and per must be whole numbers") from None
    if page < 1 or page > 1_000_000:
        raise BadRequest("page must be between 1 and 1000000")
    if per not in PAGE_SIZES:
        raise BadRequest(f"per must be one of {', '.join(map(str, PAGE_SIZES))}")
    latest = one.get("latest", "") in ("1", "true")
    return ListQuery(filters, q, sort, direction == "desc", page, per, latest)


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
    "seed",
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
    """One episode as the viewer shows it: its row and the rows of its tree nodes, steps, calls and messages, and
    the query time (ms)."""

    meta: dict[str, Any]
    nodes: list[dict[str, Any]]
    steps: list[dict[str, Any]]
    calls: list[dict[str, Any]]
    messages: list[dict[str, Any]]
    elapsed_ms: float


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
    out = Episode(m, mine("viewer_nodes"), mine("viewer_steps"), mine("viewer_calls"), mine("viewer_messages"), 0.0)
    out.elapsed_ms = (time.perf_counter() - t0) * 1000
    return out


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
        "SELECT w.pos, w.seq, m.role, m.kind, m.pinned, m.node_id, m.content FROM w "
        "LEFT JOIN messages m ON m.run_id = $r AND m.episode_id = $e AND m.seq = w.seq ORDER BY w.pos",
        {"r": run_id, "e": episode_id, "c": call_index},
    ).dicts()
    return call[0], msgs


# -- compare -----------------------------------------------------------------------------------------


@dataclass
class Comparison:
    """Two runs or two arms (``kind``) compared on the units both ran: successes, discordant pairs with the
    clustered McNemar p, cost difference (a minus b) with a permutation p, overall and per task. Both tests swap
    the two sides within an instance, all its seeds together (:mod:`reports.stats`); with one seed per instance
    they are the exact McNemar test and the ordinary paired sign-flip test. ``instances`` counts the paired
    instances (group, split, task, instance); ``cost_test`` says how the cost p was computed."""

    kind: str  # "run" or "arm"
    a: str
    b: str
    per_task: list[dict[str, Any]]
    pairs: int
    a_successes: int
    b_successes: int
    a_only: int
    b_only: int
    p_value: float
    mean_cost_diff: float | None
    cost_p: float | None
    discordant: list[dict[str, Any]]
    elapsed_ms: float
    instances: int = 0
    cost_test: SignFlipTest | None = None


#: per-unit outcomes. Two runs: each run's latest attempt of each unit, paired on the unit's arm,
#: model and instance (the terminal view keeps one run per unit, so it cannot pair two runs). Two
#: arms: the terminal rows, paired like paired_methods.sql (model, split, task, instance, seed).
def _side_sql(kind: str, columns: set[str]) -> str:
    """Per-unit outcomes of one side. Two runs: each run's own counted row of each unit (its
    latest finished attempt, else its latest), paired on the unit's arm, model and instance (the
    terminal view keeps one run per unit, so it cannot pair two runs). Two arms: the rows the
    report's paired table counts (terminal, finished), paired like reports/sql/paired_methods.sql
    on model, split, task, instance and seed."""
    cols = (
        "SELECT {side} AS side, {grp} AS grp, env_split, task, instance_id, seed, run_id, episode_id, success, "
        "cost_usd, end_reason, mode FROM _episode_list "
    )
    finished_first = "finished DESC, " if "finished" in columns else ""
    if kind == "run":
        return (
            cols.format(side="run_id", grp="arm || ' · ' || model_label")
            + f"QUALIFY row_number() OVER (PARTITION BY run_id, unit_id ORDER BY {finished_first}attempt DESC, "
            "ended_at DESC, episode_id DESC) = 1"
        )
    counted = "is_unit_row" if "is_unit_row" in columns else "is_latest"
    # several runs may hold the same (arm, model, instance, seed): the latest row counts, as in paired_methods.sql
    return (
        cols.format(side="arm", grp="model_label")
        + f"WHERE {counted}"
        + (" AND finished" if "finished" in columns else "")
        + " QUALIFY row_number() OVER (PARTITION BY arm, model_label, env_split, task, instance_id, seed "
        "ORDER BY ended_at DESC, run_id DESC, episode_id DESC) = 1"
    )


def compare(snap: Snapshot, kind: str, a: str, b: str) -> Comparison:
    """Compare ``a`` with ``b`` (two run ids or two arm labels) on paired units (see :func:`_side_sql`); a 400
    for an unknown kind, an unknown side or the same side twice."""
    t0 = time.perf_counter()
    if kind not in ("run", "arm"):
        raise BadRequest("compare what? kind must be run or arm")
    col = "run_id" if kind == "run" else "arm"
    known = {str(v) for v in snap.query(f"SELECT DISTINCT {col} FROM _episode_list").column(col)}
    for side in (a, b):
        if side not in known:
            raise BadRequest(f"no {kind} named {side!r}" if side else f"choose two {kind}s to compare")
    if a == b:
        raise BadRequest(f"choose two different {kind}s")
    sql = f"""
    WITH s AS ({_side_sql(kind, snap.columns)}), x AS (SELECT * FROM s WHERE side = $a), y AS (SELECT * FROM s WHERE side = $b)
    SELECT x.grp, x.env_split, x.task, x.instance_id, x.seed,
      x.run_id AS a_run, x.episode_id AS a_episode, x.success AS a_success, x.cost_usd AS a_cost, coalesce(x.mode, x.end_reason) AS a_mode,
      y.run_id AS b_run, y.episode_id AS b_episode, y.success AS b_success, y.cost_usd AS b_cost, coalesce(y.mode, y.end_reason) AS b_mode
    FROM x JOIN y ON x.grp = y.grp AND x.env_split = y.env_split AND x.task = y.task AND x.instance_id = y.instance_id AND x.seed = y.seed
    ORDER BY x.grp, x.env_split, x.task, x.instance_id, x.seed"""
    pairs = snap.query(sql, {"a": a, "b": b}).dicts()
    # the unit of the tests: one instance of one group (arm and model, or model) and split
    inst = [(p["grp"], p["env_split"], p["task"], p["instance_id"]) for p in pairs]
    per: dict[tuple[str, str, str], dict[str, Any]] = {}
    for p in pairs:
        t = per.setdefault(
            (p["grp"], p["env_split"], p["task"]),
            {
                "group": p["grp"],
                "env_split": p["env_split"],
                "task": p["task"],
                "pairs": 0,
                "a_successes": 0,
                "b_successes": 0,
                "a_only": 0,
                "b_only": 0,
                "cost_diffs": [],
                "a_ok": [],
                "b_ok": [],
                "instances": [],
            },
        )
        t["pairs"] += 1
        t["a_successes"] += bool(p["a_success"])
        t["b_successes"] += bool(p["b_success"])
        t["a_only"] += bool(p["a_success"] and not p["b_success"])
        t["b_only"] += bool(p["b_success"] and not p["a_success"])
        t["cost_diffs"].append((p["a_cost"] or 0.0) - (p["b_cost"] or 0.0))
        t["a_ok"].append(bool(p["a_success"]))
        t["b_ok"].append(bool(p["b_success"]))
        t["instances"].append(p["instance_id"])
    per_task = []
    for t in per.values():
        diffs = t.pop("cost_diffs")
        keys = t.pop("instances")
        t["p_value"] = float(clustered_mcnemar_exact(instance_discordance(t.pop("a_ok"), t.pop("b_ok"), keys)))
        t["instances"] = len(set(keys))
        t["mean_cost_diff"] = sum(diffs) / len(diffs)
        per_task.append(t)
    diffs = [(p["a_cost"] or 0.0) - (p["b_cost"] or 0.0) for p in pairs]
    a_only = sum(1 for p in pairs if p["a_success"] and not p["b_success"])
    b_only = sum(1 for p in pairs if p["b_success"] and not p["a_success"])
    discordance = instance_discordance([bool(p["a_success"]) for p in pairs], [bool(p["b_success"]) for p in pairs], inst)
    cost_test = clustered_permutation_test(diffs, inst) if diffs else None
    return Comparison(
        kind,
        a,
        b,
        per_task,
        len(pairs),
        sum(bool(p["a_success"]) for p in pairs),
        sum(bool(p["b_success"]) for p in pairs),
        a_only,
        b_only,
        float(clustered_mcnemar_exact(discordance)),
        sum(diffs) / len(diffs) if diffs else None,
        cost_test.p if cost_test else None,
        [p for p in pairs if bool(p["a_success"]) != bool(p["b_success"])],
        (time.perf_counter() - t0) * 1000,
        len(set(inst)),
        cost_test,
    )


def compare_choices(snap: Snapshot) -> dict[str, list[str]]:
    """The run ids and arm labels a comparison can choose from, sorted."""
    return {
        "run": [str(v) for v in snap.query("SELECT DISTINCT run_id FROM _episode_list ORDER BY 1").column("run_id")],
        "arm": [str(v) for v in snap.query("SELECT DISTINCT arm FROM _episode_list ORDER BY 1").column("arm")],
    }
