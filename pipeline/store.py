"""The run folder: identity (run.json), the plan, the spec copy, and tolerant table reads.

A run folder is a local path or an object-store URI (anything ``pyarrow.fs`` understands).
``run.json`` is written once when the run starts and names the run; pointing a *different* run
at the folder is an error, so two sweeps can never interleave their rows. Reads skip part files
that cannot be read and report them (a crash can leave a truncated temp file; a reader must not
die on it). Parts written under an earlier schema version are mapped to the current one as they
are read (:mod:`schemas.versions`); a run folder of another version is read, not continued.

One driver at a time: ``driver.lock`` is taken with an exclusive ``flock`` on an open file,
atomically, and held for the driver's whole session; the kernel releases it when the driver's
process ends, however it ends, so a lock left by a crashed driver is free (stale) without any
pid guessing. The file also names its holder (pid, host) for the refusal message. For an
object-store run folder the lock is the local mirror's (one driver per machine), plus the
holder file on the store (checked, then written: best effort between machines).
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.fs as pafs

from pipeline.errors import RunFolderError
from pipeline.mirror import mirror_dir
from schemas.parts import RUN_FILE, BadPart, inspect_parts, is_part_name, part_files, read_parts
from schemas.records import SCHEMA_VERSION
from schemas.tables import TABLES
from schemas.versions import continues
from workers.sink import is_uri

LOCK_FILE = "driver.lock"
PLAN_FILE = "plan.json"
SPEC_FILE = "spec.yaml"


@dataclass(frozen=True)
class RunIdentity:
    """The content of run.json: which run owns the folder (``run`` is the spec's name, ``run_id`` unique per
    folder) and the schema version its rows were written under; ``wiki_manifest_sha256``: the
    digest of the manifest over the Wikipedia pages the run recorded, written when a session ends
    (workers/envs/fever/manifest.py; None: no page recorded, or a run.json of an earlier recap)."""

    run_id: str
    run: str
    created_at: float
    schema_version: int = SCHEMA_VERSION
    wiki_manifest_sha256: str | None = None

    def to_json(self) -> str:
        """The file's text; ``wiki_manifest_sha256`` only when set, so a run that recorded no
        Wikipedia page keeps the run.json an earlier recap reads."""
        fields = {k: v for k, v in self.__dict__.items() if not (k == "wiki_manifest_sha256" and v is None)}
        return json.dumps(fields, indent=2, sort_keys=True)


class RunStore:
    """Files of one run folder (local or object store)."""

    def __init__(self, location: str | Path) -> None:
        self.location = str(location)
        self.remote = is_uri(self.location)
        if self.remote:
            self.fs, self.root = pafs.FileSystem.from_uri(self.location)
            self.root = self.root.rstrip("/")
        else:
            self.path = Path(self.location)
        #: the open, flock'd lock file while this store holds the driver lock
        self._lock_fd: int | None = None

    def __str__(self) -> str:
        return self.location

    # -- small files ------------------------------------------------------------------------------
    def _p(self, name: str) -> str:
        return f"{self.root}/{name}" if self.remote else str(self.path / name)

    def exists(self, name: str = "") -> bool:
        """Whether ``name`` (or, with no name, the folder itself) exists in the run folder."""
        if self.remote:
            info = self.fs.get_file_info(self._p(name) if name else self.root)
            return info.type != pafs.FileType.NotFound
        return (self.path / name).exists() if name else self.path.exists()

    def is_empty(self) -> bool:
        """True when the folder is missing or holds nothing (a fresh run may start there)."""
        if self.remote:
            info = self.fs.get_file_info(self.root)
            if info.type == pafs.FileType.NotFound:
                return True
            return not self.fs.get_file_info(pafs.FileSelector(self.root, recursive=False))
        return not self.path.exists() or (self.path.is_dir() and not any(self.path.iterdir()))

    def read_text(self, name: str) -> str | None:
        """The text of ``name`` in the folder; None when it is missing or cannot be read."""
        try:
            if self.remote:
                with self.fs.open_input_stream(self._p(name)) as fh:
                    return fh.read().decode()
            return (self.path / name).read_text()
        except (FileNotFoundError, OSError):
            return None

    def read_bytes(self, name: str) -> bytes | None:
        """The bytes of ``name`` in the folder; None when it is missing or cannot be read."""
        try:
            if self.remote:
                with self.fs.open_input_stream(self._p(name)) as fh:
                    return fh.read()
            return (self.path / name).read_bytes()
        except (FileNotFoundError, OSError):
            return None

    def write_bytes(self, name: str, data: bytes) -> None:
        """Atomic write of bytes (temp + fsync + rename locally; one PUT on an object store)."""
        if self.remote:
            parent = self._p(name).rsplit("/", 1)[0]
            self.fs.create_dir(parent, recursive=True)
            with self.fs.open_output_stream(self._p(name)) as fh:
                fh.write(data)
            return
        dest = self.path / name
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".tmp-{dest.name}-{uuid.uuid4().hex[:6]}")
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, dest)

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
        """The run.json of this folder, or None when there is none; a malformed one raises RunFolderError."""
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
            if not self.is_empty() and not self._only_lock():
                raise RunFolderError(f"output folder {self.location} is not empty and holds no {RUN_FILE}; choose a new folder")
            if not self.remote:
                self._check_creatable()
            return None
        if ident.run != run_name:
            raise RunFolderError(
                f"output folder {self.location} holds run {ident.run!r} (run_id {ident.run_id}), not {run_name!r}; "
                "choose another output folder or use the same run name"
            )
        if not continues(ident.schema_version):
            # readers map the parts of an earlier version (schemas.versions), so status, sql,
            # show and report read such a run; a run is not continued under another version
            # (its units would be written in two shapes) unless that version's parts differ
            # only by columns filled on read (schemas.versions.continues)
            older = ident.schema_version < SCHEMA_VERSION
            raise RunFolderError(
                f"output folder {self.location} was written with schema version {ident.schema_version}, this recap writes "
                f"{SCHEMA_VERSION}: "
                + (
                    "its rows stay readable (recap status, sql, show, report); continue the sweep in a new output folder"
                    if older
                    else "use the recap version that wrote it"
                )
            )
        return ident

    def _only_lock(self) -> bool:
        """The folder holds nothing but the driver lock (a driver starting, or one that crashed
        before it wrote run.json) and temp files."""
        try:
            if self.remote:
                names = [i.base_name for i in self.fs.get_file_info(pafs.FileSelector(self.root, recursive=False))]
            else:
                names = [p.name for p in self.path.iterdir()]
        except OSError:
            return False
        return all(n == LOCK_FILE or n.startswith(".tmp-") for n in names)

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
        """Name the folder for a new run: a fresh random ``run_id`` written to run.json."""
        ident = RunIdentity(run_id=uuid.uuid4().hex[:16], run=run_name, created_at=time.time())
        self.write_text(RUN_FILE, ident.to_json() + "\n")
        return ident

    def require_identity(self) -> RunIdentity:
        """The run.json of an existing run folder; RunFolderError (one line) when the folder is missing or is not a run folder."""
        if not self.exists():
            raise RunFolderError(f"run folder {self.location} does not exist")
        ident = self.identity()
        if ident is None:
            raise RunFolderError(f"{self.location} is not a run folder (no {RUN_FILE})")
        return ident

    # -- one driver at a time --------------------------------------------------------------------
    def _lock_path(self) -> Path:
        """The file whose flock is the lock: ``driver.lock`` in a local run folder; for an
        object-store run, a file beside its local mirror (one driver per machine)."""
        if not self.remote:
            return self.path / LOCK_FILE

        mirror = mirror_dir(self.location)
        return mirror.with_name(mirror.name + "." + LOCK_FILE)

    def _holder_text(self, path: Path) -> dict[str, Any]:
        try:
            holder = json.loads(path.read_text() or "{}")
        except (OSError, ValueError):
            holder = {}
        return holder if isinstance(holder, dict) else {}

    def lock_holder(self) -> dict[str, Any] | None:
        """The driver holding the folder (pid, host), or None when free or its holder is dead.

        Decided by the flock, not by the file's contents: a crashed driver's lock is free."""
        path = self._lock_path()
        holder: dict[str, Any] | None = None
        if path.exists():
            try:
                fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
            except OSError:
                fd = -1
            if fd >= 0:
                try:
                    fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
                    fcntl.flock(fd, fcntl.LOCK_UN)  # free: nobody holds it (or its holder died)
                except BlockingIOError:
                    holder = self._holder_text(path) or {"pid": "?", "host": "?"}
                except OSError:  # a file system without locks: fall back on the holder's pid
                    holder = self._legacy_holder(path.read_text() if path.exists() else None)
                finally:
                    os.close(fd)
        if holder is None and self.remote:  # a driver on another machine
            holder = self._remote_holder()
        return holder

    def _remote_holder(self) -> dict[str, Any] | None:
        """The holder an object-store run folder's lock file names on *another* machine (on
        this one the mirror's flock decides)."""
        holder = self._legacy_holder(self.read_text(LOCK_FILE))
        if holder is None or holder.get("host") == socket.gethostname():
            return None
        return holder

    def _legacy_holder(self, text: str | None) -> dict[str, Any] | None:
        """The holder a lock file names, unless it is on this host and its process is gone."""
        if not text:
            return None
        try:
            holder = json.loads(text)
        except ValueError:
            return None
        if not isinstance(holder, dict):
            return None
        if holder.get("host") == socket.gethostname():
            try:
                os.kill(int(holder["pid"]), 0)
            except (OSError, ValueError, KeyError, TypeError):
                return None  # its driver is gone (a crash): the lock is stale
        return holder

    def _in_use(self, holder: dict[str, Any]) -> RunFolderError:
        if self.remote and holder.get("host") not in (None, "?", socket.gethostname()):
            hint = f"wait for it, or delete {LOCK_FILE} there if that driver is gone"
        else:
            hint = "wait for it to finish (a driver that dies releases the lock by itself)"
        return RunFolderError(
            f"run folder {self.location} is in use by another driver (pid {holder.get('pid')} on {holder.get('host')}); {hint}"
        )

    def check_unlocked(self) -> None:
        """Raise RunFolderError when a live driver holds this folder's lock (a stale lock passes); takes nothing."""
        holder = self.lock_holder()
        if holder is not None:
            raise self._in_use(holder)

    def acquire_lock(self, wait_s: float = 0.5) -> None:
        """Take the driver lock atomically and hold it until :meth:`release_lock` (or the
        process ends). Waits up to ``wait_s`` for a lock that is only being looked at; a lock
        held by a live driver is refused (:class:`RunFolderError`, one line)."""
        if self._lock_fd is not None:
            raise RunFolderError(f"run folder {self.location}: this process already holds its driver lock")
        path = self._lock_path()
        path.parent.mkdir(parents=True, exist_ok=True)
        deadline = time.monotonic() + wait_s
        while True:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                if time.monotonic() >= deadline:
                    raise self._in_use(self._holder_text(path) or {"pid": "?", "host": "?"}) from None
                time.sleep(0.02)
                continue
            except OSError as exc:
                os.close(fd)
                if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                    self._acquire_unlocked_fs()
                    return
                raise
            # the file we locked must still be the one at the path (a releasing holder unlinks it)
            try:
                same = os.path.samestat(os.fstat(fd), os.stat(path))
            except FileNotFoundError:
                same = False
            if not same:
                os.close(fd)
                continue
            break
        self._lock_fd = fd
        holder = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()}).encode()
        os.ftruncate(fd, 0)
        os.pwrite(fd, holder, 0)
        if self.remote:
            try:
                self.check_remote_unlocked()
                self.write_text(LOCK_FILE, holder.decode())
            except BaseException:
                self.release_lock()
                raise

    def check_remote_unlocked(self) -> None:
        """Raise RunFolderError when the holder file on the object store names a live driver (best effort between machines)."""
        holder = self._remote_holder()
        if holder is not None:
            raise self._in_use(holder)

    def _acquire_unlocked_fs(self) -> None:
        """A file system without flock: exclusive create, then the holder check (best effort)."""
        path = self._lock_path()
        holder = json.dumps({"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()})
        for _ in range(2):
            try:
                fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o644)
            except FileExistsError:
                found = self._legacy_holder(path.read_text() if path.exists() else None)
                if found is not None:
                    raise self._in_use(found) from None
                path.unlink(missing_ok=True)  # stale: its driver is gone
                continue
            os.write(fd, holder.encode())
            os.close(fd)
            self._lock_fd = -1
            return
        raise RunFolderError(f"run folder {self.location}: could not take the driver lock {path}")

    def release_lock(self) -> None:
        """Give the driver lock back (the object store's holder file too, when it is ours); a no-op when not held."""
        fd = self._lock_fd
        if fd is None:
            return
        self._lock_fd = None
        if self.remote:
            try:
                text = self.read_text(LOCK_FILE)
                if text and json.loads(text).get("pid") == os.getpid():
                    self.fs.delete_file(self._p(LOCK_FILE))
            except Exception:
                pass
        path = self._lock_path()
        try:
            # unlink while still holding it: a driver that opened the old file finds it gone
            # (the inode check in acquire_lock) and takes a fresh one
            if fd >= 0:
                if os.path.samestat(os.fstat(fd), os.stat(path)):
                    path.unlink()
            else:
                path.unlink(missing_ok=True)
        except OSError:
            pass
        finally:
            if fd >= 0:
                os.close(fd)  # releases the flock

    # -- tables ------------------------------------------------------------------------------------
    def part_files(self, table: str) -> list[str]:
        """Paths of the table's part files (``part-*.parquet``), sorted; temp files and other names are not parts."""
        if self.remote:
            sel = pafs.FileSelector(f"{self.root}/{table}", allow_not_found=True)
            return sorted(
                i.path for i in self.fs.get_file_info(sel) if i.type == pafs.FileType.File and is_part_name(i.base_name)
            )
        return [str(p) for p in part_files(self.path, table)]

    def _open_part(self, path: str) -> Any:
        return self.fs.open_input_file(path) if self.remote else path

    def read_table(self, table: str, columns: list[str] | None = None) -> tuple[pa.Table, list[BadPart]]:
        """Every row of ``table``'s good part files (optionally a few columns) and the bad ones,
        by the one rule every reader applies (``schemas.parts.schema_problem``): a part with a
        missing column or another type is skipped and named, never cast."""
        return read_parts(self.part_files(table), table, columns, self._open_part if self.remote else None)

    def check_parts(self, table: str) -> list[BadPart]:
        """The bad part files of ``table``, found from their footers alone (truncated, corrupt,
        or not matching the table's schema) - cheap enough to run over every table."""
        return inspect_parts(self.part_files(table), table, self._open_part if self.remote else None)[1]

    def tables(self) -> list[str]:
        """The run tables' names (schemas.tables), whether or not this folder has parts for them."""
        return list(TABLES)

    def read_json(self, name: str) -> Any:
        """The parsed JSON file ``name``, or None when it is missing; malformed JSON raises ValueError."""
        text = self.read_text(name)
        return None if text is None else json.loads(text)
