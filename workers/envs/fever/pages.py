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
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import pyarrow as pa
import pyarrow.parquet as pq

#: the table name in a run folder, and the file name :func:`write_pages` uses
TABLE = "wiki_pages"

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


def _table_files(folder: Path) -> list[Path]:
    if folder.is_file():
        return [folder]
    direct = folder / f"{TABLE}.parquet"
    nested = sorted((folder / TABLE).glob("*.parquet")) if (folder / TABLE).is_dir() else []
    return ([direct] if direct.is_file() else []) + nested


class Snapshot:
    """The answers of earlier runs by request URL: ``DIR/wiki_pages.parquet`` and/or
    ``DIR/wiki_pages/*.parquet`` (or one Parquet file). When a URL was read more than once the
    first answer read is kept. Every body is checked against its sha256 on loading."""

    def __init__(self, folder: str | Path) -> None:
        self.folder = Path(folder).expanduser()
        files = _table_files(self.folder)
        if not files:
            raise SnapshotError(f"{str(self.folder)!r} holds no {TABLE}.parquet nor {TABLE}/*.parquet")
        self._by_url: dict[str, PageRecord] = {}
        for file in files:
            for row in pq.read_table(file, schema=SCHEMA).to_pylist():
                record = PageRecord(**row)
                if sha256_hex(record.body) != record.sha256:
                    raise SnapshotError(f"{file}: the body of {record.url!r} does not match its sha256 {record.sha256}")
                self._by_url.setdefault(record.url, record)

    def get(self, url: str) -> PageRecord | None:
        """The recorded answer for ``url``, or None."""
        return self._by_url.get(url)

    def __len__(self) -> int:
        return len(self._by_url)
