"""Every Wikipedia answer a FEVER run reads, kept content-addressed, and read back for offline replay.

Why: live Wikipedia changes, so an observation is reproducible only from the bytes that produced
it. Each answer is one :class:`PageRecord` (the request URL as key, the sha256 of the body, the
HTTP status, when it was fetched, the body and the text encoding it was decoded with). A
:class:`PageStore` receives them as they are read (a run folder writes them as its ``wiki_pages``
Parquet table, :func:`write_pages`); :class:`Snapshot` reads such tables back so that
``wikipedia: snapshot:DIR`` answers every request from them, and a request they do not hold is an
error rather than a live fetch.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import pyarrow as pa
import pyarrow.parquet as pq

from schemas.parts import read_table
from schemas.records import WikiPageRecord, WikiRequestRecord

#: the table name of the bodies in a run folder, and the file name :func:`write_pages` uses
TABLE = "wiki_pages"
#: the table of a run folder that maps each request URL to its body's sha256
REQUESTS_TABLE = "wiki_requests"

SCHEMA = pa.schema(
    [
        ("url", pa.string()),
        ("sha256", pa.string()),
        ("status", pa.int32()),
        ("fetched_at", pa.string()),
        ("final_url", pa.string()),
        ("encoding", pa.string()),
        ("body", pa.binary()),
    ]
)


def sha256_hex(body: bytes) -> str:
    """The content address of a body."""
    return hashlib.sha256(body).hexdigest()


@dataclass(frozen=True)
class PageRecord:
    """One answer as read: ``url`` is the request URL (the key), ``final_url`` where redirects led,
    ``encoding`` the text encoding the body was decoded with, ``fetched_at`` ISO 8601 UTC."""

    url: str
    sha256: str
    status: int
    fetched_at: str
    body: bytes
    encoding: str
    final_url: str = ""

    def text(self) -> str:
        """The body as text, decoded as the HTTP client decoded it (``requests``' ``Response.text``:
        the recorded encoding, undecodable bytes replaced)."""
        return decode_body(self.body, self.encoding)


def decode_body(body: bytes, encoding: str) -> str:
    """``requests.Response.text`` for a known encoding: replace what does not decode; an unknown
    encoding name falls back to the default codec (requests/models.py, ``Response.text``)."""
    try:
        return str(body, encoding, errors="replace")
    except (LookupError, TypeError):
        return str(body, errors="replace")


class PageStore(Protocol):
    """Where the answers a run reads go (a run folder's ``wiki_pages`` table, or memory)."""

    def append(self, record: PageRecord) -> None:
        """Keep one answer."""
        ...


class MemoryPageStore:
    """Answers kept in memory in reading order (tests, and a worker's buffer before it writes)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.records: list[PageRecord] = []

    def append(self, record: PageRecord) -> None:
        """Keep one answer."""
        with self._lock:
            self.records.append(record)


def write_pages(records: Iterable[PageRecord], path: str | Path) -> Path:
    """Write ``records`` as one Parquet file (the ``wiki_pages`` table's layout) and return its path."""
    rows = list(records)
    table = pa.table(
        {
            "url": [r.url for r in rows],
            "sha256": [r.sha256 for r in rows],
            "status": [r.status for r in rows],
            "fetched_at": [r.fetched_at for r in rows],
            "final_url": [r.final_url for r in rows],
            "encoding": [r.encoding for r in rows],
            "body": [r.body for r in rows],
        },
        schema=SCHEMA,
    )
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, out)
    return out


class SnapshotError(ValueError):
    """A snapshot folder that holds no ``wiki_pages`` table, or a row whose body is not its sha256."""


def _checked(record: PageRecord, where: object) -> PageRecord:
    if sha256_hex(record.body) != record.sha256:
        raise SnapshotError(f"{where}: the body of {record.url!r} does not match its sha256 {record.sha256}")
    return record


def _page_file_records(folder: Path) -> Iterator[PageRecord]:
    """The records of :func:`write_pages` files (one table holding URLs and bodies)."""
    files = _table_files(folder)
    if not files:
        raise SnapshotError(f"{str(folder)!r} holds no {TABLE}.parquet nor {TABLE}/*.parquet")
    for file in files:
        for row in pq.read_table(file, schema=SCHEMA).to_pylist():
            yield _checked(PageRecord(**row), file)


def _run_folder_records(run_dir: Path) -> Iterator[PageRecord]:
    """A run folder's requests joined to their bodies (schemas.records.WikiRequestRecord /
    WikiPageRecord); a request whose body is missing is an error, not a silent miss."""
    pages, bad = read_table(run_dir, TABLE)
    requests, bad_requests = read_table(run_dir, REQUESTS_TABLE)
    if bad or bad_requests:
        first = (bad + bad_requests)[0]
        raise SnapshotError(f"{str(run_dir)!r}: a wiki table part cannot be read ({first})")
    bodies = {row["sha256"]: row["body"] for row in pages.select(["sha256", "body"]).to_pylist()}
    for row in requests.to_pylist():
        body = bodies.get(row["sha256"])
        if body is None:
            raise SnapshotError(f"{str(run_dir)!r}: the body of {row['url']!r} (sha256 {row['sha256']}) is not in {TABLE}")
        yield _checked(
            PageRecord(
                url=row["url"],
                sha256=row["sha256"],
                status=row["status"],
                fetched_at=row["fetched_at"],
                body=body,
                encoding=row["encoding"],
                final_url=row["final_url"],
            ),
            run_dir,
        )


def _table_files(folder: Path) -> list[Path]:
    if folder.is_file():
        return [folder]
    direct = folder / f"{TABLE}.parquet"
    nested = sorted((folder / TABLE).glob("*.parquet")) if (folder / TABLE).is_dir() else []
    return ([direct] if direct.is_file() else []) + nested


def snapshot_key(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """What a snapshot of ``folder`` was read from: each table file's path, size and mtime.

    Why not the folder's mtime: a run still writing adds part files inside ``wiki_pages/`` and
    ``wiki_requests/``, which leaves the run folder's own mtime as it was; a cache keyed on it
    would keep answering from the parts it first saw."""
    files: list[Path] = [folder] if folder.is_file() else []
    for table in (TABLE, REQUESTS_TABLE):
        if (folder / f"{table}.parquet").is_file():
            files.append(folder / f"{table}.parquet")
        if (folder / table).is_dir():
            files += sorted(p for p in (folder / table).glob("*.parquet") if not p.name.startswith("."))
    key = []
    for f in files:
        try:
            st = f.stat()
        except FileNotFoundError:  # removed between listing and stat: not part of what is read
            continue
        key.append((str(f), st.st_size, st.st_mtime_ns))
    return tuple(key)


class Snapshot:
    """The answers of earlier runs by request URL, from a run folder (its ``wiki_requests`` and
    ``wiki_pages`` tables: each request joined to its body by sha256), or from
    ``DIR/wiki_pages.parquet`` and/or ``DIR/wiki_pages/*.parquet`` written by :func:`write_pages`
    (or one such Parquet file). When a URL was read more than once the first answer read is kept.
    Every body is checked against its sha256 on loading."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).expanduser()
        self._by_url: dict[str, PageRecord] = {}
        if (self.folder / REQUESTS_TABLE).is_dir():
            records: Iterable[PageRecord] = _run_folder_records(self.folder)
        else:
            records = _page_file_records(self.folder)
        for record in records:
            self._by_url.setdefault(record.url, record)

    def get(self, url: str) -> PageRecord | None:
        """The recorded answer for ``url``, or None."""
        return self._by_url.get(url)

    def __len__(self) -> int:
        return len(self._by_url)


class RunRecords:
    """The page records of one environment, handed to the episode worker as table rows.

    Why here: the environment reads pages; the run folder keeps them as two tables - the bodies
    content-addressed (``wiki_pages``, one row per sha256) and each request pointing at one
    (``wiki_requests``). A body is handed over once per run by this process (:data:`_SENT`
    remembers the sha256s a process has handed over for each run), so a worker that reads the
    same page in many episodes writes it once."""

    def __init__(self) -> None:
        self.store = MemoryPageStore()
        self._taken = 0

    def take(self, episode_id: str, run_id: str) -> list[Any]:
        """Records of the pages read since the last call: a ``wiki_pages`` row for each body not
        yet handed over for ``run_id``, a ``wiki_requests`` row for each request."""
        with self.store._lock:
            fresh = self.store.records[self._taken :]
            self._taken = len(self.store.records)
        out: list[Any] = []
        sent = _sent_for(run_id)
        for r in fresh:
            if r.sha256 not in sent:
                sent.add(r.sha256)
                out.append(WikiPageRecord(sha256=r.sha256, body=r.body, size=len(r.body)))
            out.append(
                WikiRequestRecord(
                    episode_id=episode_id,
                    url=r.url,
                    sha256=r.sha256,
                    status=r.status,
                    fetched_at=r.fetched_at,
                    final_url=r.final_url,
                    encoding=r.encoding,
                )
            )
        return out


#: per run id, the sha256s this process has handed over (the last few runs: a worker serves one)
_SENT: OrderedDict[str, set[str]] = OrderedDict()
_SENT_RUNS = 4
_SENT_LOCK = threading.Lock()


def _sent_for(run_id: str) -> set[str]:
    with _SENT_LOCK:
        if run_id not in _SENT:
            _SENT[run_id] = set()
            while len(_SENT) > _SENT_RUNS:
                _SENT.popitem(last=False)
        _SENT.move_to_end(run_id)
        return _SENT[run_id]
