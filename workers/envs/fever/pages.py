"""Every Wikipedia answer a FEVER run reads, kept content-addressed, and read back for offline replay.

Why: live Wikipedia changes, so an observation is reproducible only from the bytes that produced
it. Each answer is one :class:`PageRecord` (the request URL as key, the sha256 of the body, the
HTTP status, when it was fetched, the body and the text encoding it was decoded with). A
:class:`PageStore` receives them as they are read (a run folder writes them as its ``wiki_pages``
Parquet table, :func:`write_pages`); :class:`Snapshot` reads such tables back so that
``wikipedia: snapshot:DIR`` answers every request from them, and a request they do not hold is an
error rather than a live fetch. A snapshot is served only when it matches its sealed manifest
(:mod:`.manifest`: a hash per request row over every field served, the run's digest in
``run.json``); :func:`seal_run_folder` writes it when a run ends, :func:`write_pages` beside its file.
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

from schemas.parts import RUN_FILE, read_run_file, read_table
from schemas.records import WikiPageRecord, WikiRequestRecord

from .manifest import MANIFEST_FILE, RUN_KEY, Entry, SnapshotError, manifest_path, record_sha256, verify, write_manifest

__all__ = ["SnapshotError"]  # defined with the manifest it guards; importers reach it here too

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

    def record_sha256(self) -> str:
        """The row hash (:func:`.manifest.record_sha256`) over every field served of this answer."""
        return record_sha256(self.url, self.status, self.encoding, self.final_url, self.fetched_at, self.sha256)

    def entry(self) -> Entry:
        """This answer's manifest entry: (URL, row hash)."""
        return (self.url, self.record_sha256())

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
    root = _pages_root(out)
    write_manifest(root, [r.entry() for r in _page_file_records(root, checked=False)])  # bodies are checked on loading
    return out


def _pages_root(file: Path) -> Path:
    """The snapshot a :func:`write_pages` file belongs to: ``DIR`` for ``DIR/wiki_pages.parquet``
    and ``DIR/wiki_pages/*.parquet``, else the file itself."""
    if file.name == f"{TABLE}.parquet":
        return file.parent
    if file.parent.name == TABLE:
        return file.parent.parent
    return file


def _checked(record: PageRecord, where: object) -> PageRecord:
    if sha256_hex(record.body) != record.sha256:
        raise SnapshotError(f"{where}: the body of {record.url!r} does not match its sha256 {record.sha256}")
    return record


def _page_file_records(folder: Path, *, checked: bool = True) -> Iterator[PageRecord]:
    """The records of :func:`write_pages` files (one table holding URLs and bodies)."""
    files = _table_files(folder)
    if not files:
        raise SnapshotError(f"{str(folder)!r} holds no {TABLE}.parquet nor {TABLE}/*.parquet")
    for file in files:
        for row in pq.read_table(file, schema=SCHEMA).to_pylist():
            yield _checked(PageRecord(**row), file) if checked else PageRecord(**row)


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


def seal_run_folder(run_dir: Path) -> str | None:
    """Write the manifest of ``run_dir``'s ``wiki_requests`` rows (every row's URL and row hash) and
    return its digest, for run.json (:data:`.manifest.RUN_KEY`); None when the run read no page.
    Called by the driver when a session ends (pipeline/driver.py). SnapshotError when a part of
    the table cannot be read (nothing is sealed then)."""
    requests, bad = read_table(run_dir, REQUESTS_TABLE)
    if bad:
        raise SnapshotError(f"{str(run_dir)!r}: a {REQUESTS_TABLE} part cannot be read ({bad[0]}); nothing sealed")
    if requests.num_rows == 0:
        return None
    entries = [
        (r["url"], record_sha256(r["url"], r["status"], r["encoding"], r["final_url"], r["fetched_at"], r["sha256"]))
        for r in requests.select(["url", "status", "encoding", "final_url", "fetched_at", "sha256"]).to_pylist()
    ]
    return write_manifest(run_dir, entries)


def snapshot_key(folder: Path) -> tuple[tuple[str, int, int], ...]:
    """What a snapshot of ``folder`` was read from: each table file's path, size and mtime, and
    those of its manifest and run.json (a run that ends seals again).

    Why not the folder's mtime: a run still writing adds part files inside ``wiki_pages/`` and
    ``wiki_requests/``, which leaves the run folder's own mtime as it was; a cache keyed on it
    would keep answering from the parts it first saw."""
    files: list[Path] = [folder, manifest_path(folder)] if folder.is_file() else [folder / RUN_FILE, folder / MANIFEST_FILE]
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
    Every body is checked against its sha256 on loading, and the rows against the sealed manifest
    (:func:`.manifest.verify`): SnapshotError, one line, for any difference or no manifest."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).expanduser()
        self._by_url: dict[str, PageRecord] = {}
        run_folder = (self.folder / REQUESTS_TABLE).is_dir()
        if run_folder:
            records = list(_run_folder_records(self.folder))
            sealed = (read_run_file(self.folder) or {}).get(RUN_KEY)
        else:
            records = list(_page_file_records(self.folder))
            sealed = None
        verify(self.folder, [r.entry() for r in records], sealed if isinstance(sealed, str) else None, run_folder=run_folder)
        for record in records:
            self._by_url.setdefault(record.url, record)

    def get(self, url: str) -> PageRecord | None:
        """The recorded answer for ``url``, or None."""
        return self._by_url.get(url)

    def __len__(self) -> int:
        return len(self._by_url)

    def servers(self) -> list[str]:
        """The base URLs its requests were made to (``<base>/w/index.php?search=...`` or
        ``<base>/wiki/...``: ``http://127.0.0.1:8080``, ``https://en.wikipedia.org``), sorted: the
        ``wikipedia_url`` the recording run used, read from its sealed rows."""
        bases = set()
        for url in self._by_url:
            for marker in ("/w/index.php", "/wiki/"):
                if marker in url:
                    bases.add(url.split(marker, 1)[0])
                    break
        return sorted(bases)


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
