"""The run folder: identity (run.json), the plan, the spec copy, and tolerant table reads.

A run folder is a local path or an object-store URI (anything ``pyarrow.fs`` understands).
``run.json`` is written once when the run starts and names the run; pointing a *different* run
at the folder is an error, so two sweeps can never interleave their rows. Reads skip part files
that cannot be read and report them (a crash can leave a truncated temp file; a reader must not
die on it).
"""

from __future__ import annotations

import json
import os
import socket
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.errors import RunFolderError
from schemas.records import SCHEMA_VERSION
from schemas.tables import TABLES, arrow_schema
from workers.sink import is_uri
from workers.storage import BadPart

RUN_FILE = "run.json"
LOCK_FILE = "driver.lock"
PLAN_FILE = "plan.json"
SPEC_FILE = "spec.yaml"


@dataclass(frozen=True)
class RunIdentity:
    run_id: str
    run: str
    created_at: float
    schema_version: int = SCHEMA_VERSION

    def to_json(self) -> str:
        return json.dumps(self.__dict__, indent=2, sort_keys=True)


class RunStore:
    """Files of one run folder (local or object store)."""

    def __init__(self, location: str | Path) -> None:
        self.location = str(location)
        self.remote = is_uri(self.location)
        if self.remote:
            import pyarrow.fs as pafs

            self.fs, self.root = pafs.FileSystem.from_uri(self.location)
            self.root = self.root.rstrip("/")
        else:
            self.path = Path(self.location)

    def __str__(self) -> str:
        return self.location

    # -- small files ------------------------------------------------------------------------------
    def _p(self, name: str) -> str:
        return f"{self.root}/{name}" if self.remote else str(self.path / name)

    def exists(self, name: str = "") -> bool:
        if self.remote:
            import pyarrow.fs as pafs

            info = self.fs.get_file_info(self._p(name) if name else self.root)
            return info.type != pafs.FileType.NotFound
        return (self.path / name).exists() if name else self.path.exists()

    def is_empty(self) -> bool:
        if self.remote:
            import pyarrow.fs as pafs

            info = self.fs.get_file_info(self.root)
            if info.type == pafs.FileType.NotFound:
                return True
            return not self.fs.get_file_info(pafs.FileSelector(self.root, recursive=False))
        return not self.path.exists() or (self.path.is_dir() and not any(self.path.iterdir()))

    def read_text(self, name: str) -> str | None:
        try:
            if self.remote:
                with self.fs.open_input_stream(self._p(name)) as fh:
                    return fh.read().decode()
            return (self.path / name).read_text()
        except (FileNotFoundError, OSError):
            return None

    def write_text(self, name: str, text: str) -> None:
        """Atomic write (temp + rename locally; one PUT on an object store)."""
        if self.remote:
            self.fs.create_dir(self.root, recursive=True)
            with self.fs.open_output_stream(self._p(name)) as fh:
                fh.write(text.encode())
            return
        self.path.mkdir(parents=True, exist_ok=True)
        tmp = self.path / f".tmp-{name}-{uuid.uuid4().hex[:6]}"
        with open(tmp, "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, self.path / name)

    # -- identity --------------------------------------------------------------------------------
    def identity(self) -> RunIdentity | None:
        text = self.read_text(RUN_FILE)
        if text is None:
            return None
        try:
            data = json.loads(text)
            return RunIdentity(**data)
        except (ValueError, TypeError) as exc:
            raise RunFolderError(f"{self._p(RUN_FILE)} is not a valid run file: {exc}") from None

    def check_can_hold(self, run_name: str) -> RunIdentity | None:
        """The identity of the run already here (None for a fresh folder); an error when the
        folder holds another run or unrelated files. Writes nothing."""
        ident = self.identity()
        if ident is None:
            if not self.remote and self.path.exists() and not self.path.is_dir():
                raise RunFolderError(f"output folder {self.location} is a file; choose a folder")
            if not self.is_empty():
                raise RunFolderError(f"output folder {self.location} is not empty and holds no {RUN_FILE}; choose a new folder")
            if not self.remote:
                self._check_creatable()
            return None
        if ident.run != run_name:
            raise RunFolderError(
                f"output folder {self.location} holds run {ident.run!r} (run_id {ident.run_id}), not {run_name!r}; "
                "choose another output folder or use the same run name"
            )
        if ident.schema_version != SCHEMA_VERSION:
            raise RunFolderError(f"output folder {self.location} was written with schema version {ident.schema_version}, this is {SCHEMA_VERSION}")
        return ident

    def _check_creatable(self) -> None:
        """A local output folder that does not exist yet must be creatable: its nearest existing
        ancestor is a writable folder (found now, not at the first write of a started run)."""
        parent = self.path.absolute()
        while not parent.exists() and parent != parent.parent:
            parent = parent.parent
        if not parent.is_dir():
            raise RunFolderError(f"output folder {self.location} cannot be created: {parent} is not a folder")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise RunFolderError(f"output folder {self.location} cannot be created: {parent} is not writable")

    def create_identity(self, run_name: str) -> RunIdentity:
        ident = RunIdentity(run_id=uuid.uuid4().hex[:16], run=run_name, created_at=time.time())
        self.write_text(RUN_FILE, ident.to_json() + "\n")
        return ident

    def require_identity(self) -> RunIdentity:
        if not self.exists():
            raise RunFolderError(f"run folder {self.location} does not exist")
        ident = self.identity()
        if ident is None:
            raise RunFolderError(f"{self.location} is not a run folder (no {RUN_FILE})")
        return ident

    # -- one driver at a time --------------------------------------------------------------------
    def lock_holder(self) -> dict[str, Any] | None:
        """The driver holding the folder (pid, host), or None when free or its holder is dead."""
        text = self.read_text(LOCK_FILE)
        if not text:
            return None
        try:
            holder = json.loads(text)
        except ValueError:
            return None
        if holder.get("host") == socket.gethostname():
            try:
                os.kill(int(holder["pid"]), 0)
            except (OSError, ValueError, KeyError):
                return None  # its driver is gone (a crash): the lock is stale
        return holder

    def check_unlocked(self) -> None:
        holder = self.lock_holder()
        if holder is not None:
            raise RunFolderError(
                f"run folder {self.location} is in use by a driver (pid {holder.get('pid')} on {holder.get('host')}); "
                f"wait for it, or delete {LOCK_FILE} there if that driver is gone"
            )

    def acquire_lock(self) -> None:
        self.check_unlocked()
        self.write_text(LOCK_FILE, json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}))

    def release_lock(self) -> None:
        text = self.read_text(LOCK_FILE)
        try:
            mine = text is not None and json.loads(text).get("pid") == os.getpid()
        except ValueError:
            mine = False
        if mine:
            if self.remote:
                self.fs.delete_file(self._p(LOCK_FILE))
            else:
                (self.path / LOCK_FILE).unlink(missing_ok=True)

    # -- tables ------------------------------------------------------------------------------------
    def part_files(self, table: str) -> list[str]:
        if self.remote:
            import pyarrow.fs as pafs

            sel = pafs.FileSelector(f"{self.root}/{table}", allow_not_found=True)
            return sorted(i.path for i in self.fs.get_file_info(sel)
                          if i.type == pafs.FileType.File and i.base_name.startswith("part-") and i.base_name.endswith(".parquet"))
        folder = self.path / table
        if not folder.is_dir():
            return []
        return sorted(str(p) for p in folder.glob("part-*.parquet"))

    def read_table(self, table: str, columns: list[str] | None = None) -> tuple[pa.Table, list[BadPart]]:
        """Every readable row of ``table`` (optionally a few columns) and the unreadable parts."""
        schema = arrow_schema(table)
        if columns is not None:
            schema = pa.schema([schema.field(c) for c in columns])
        pieces: list[pa.Table] = []
        bad: list[BadPart] = []
        for path in self.part_files(table):
            try:
                if self.remote:
                    with self.fs.open_input_file(path) as fh:
                        t = pq.read_table(fh, columns=columns)
                else:
                    t = pq.read_table(path, columns=columns)
                pieces.append(t.select(schema.names).cast(schema))
            except Exception as exc:  # truncated, corrupt, wrong schema
                bad.append(BadPart(Path(path), f"{type(exc).__name__}: {exc}".splitlines()[0][:300]))
        if not pieces:
            return schema.empty_table(), bad
        return pa.concat_tables(pieces), bad

    def check_parts(self, table: str) -> list[BadPart]:
        """The unreadable part files of ``table``, found from their footers alone (truncated,
        corrupt, or without the table's columns) - cheap enough to run over every table."""
        names = set(arrow_schema(table).names)
        bad: list[BadPart] = []
        for path in self.part_files(table):
            try:
                if self.remote:
                    with self.fs.open_input_file(path) as fh:
                        found = pq.read_schema(fh)
                else:
                    found = pq.read_schema(path)
                missing = sorted(names - set(found.names))
                if missing:
                    raise ValueError(f"not a {table} part: missing column(s) {', '.join(missing[:5])}")
            except Exception as exc:
                bad.append(BadPart(Path(path), f"{type(exc).__name__}: {exc}".splitlines()[0][:300]))
        return bad

    def tables(self) -> list[str]:
        return list(TABLES)

    def read_json(self, name: str) -> Any:
        text = self.read_text(name)
        return None if text is None else json.loads(text)
