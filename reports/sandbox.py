"""One user query in a child process under a memory limit and a time limit (``recap sql``).

Why a process: DuckDB's ``memory_limit`` covers its buffer manager only. Scalar functions that
build one huge value (``range(100000000)``, ``repeat('x', 1000000000)``, ``list_resize``) and
the conversion of a big result to Python objects are outside it; measured in one process with
``memory_limit = 256MB``, such queries reached 2 to 7 GB of RSS. A separate process can be
watched from outside and stopped whatever it is doing, and its memory goes back when it ends.

* the parent (:func:`run_limited`) starts ``python -c`` on this module with the job on stdin,
  relays the child's stdout and stderr, and polls the child's resident set every few
  milliseconds: past the memory limit, or past the time limit counted from the moment the
  child starts its query, the child is killed (SIGKILL) and one line says which limit was hit;
* the child (:func:`child_main`) opens the runs read-only with DuckDB's own limit at half the
  memory limit (most big queries then fail inside DuckDB with an Out of Memory error, which is
  reported as the same limit), caps its address space at what it has plus the limit (a single
  allocation bigger than the limit fails at once instead of being filled page by page), tells
  the parent the query starts, runs it and prints the result.

Exit status: the child's (0, or 2 with one line), 2 with one line when a limit was hit or the
child died. Nothing is written anywhere: the child's connection is the locked-down one of
:func:`reports.views.open_runs_checked`, without a spill folder.
"""

from __future__ import annotations

import codecs
import json
import math
import os
import re
import resource
import signal
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from reports.render_text import print_result
from reports.views import ReportError, open_runs_checked, run_query

#: the repository root the child imports ``reports`` from (the same code as the parent)
ROOT = Path(__file__).resolve().parents[1]

DEFAULT_MEMORY = "2GB"
DEFAULT_TIMEOUT_S = 60.0
#: below this the interpreter, DuckDB and pyarrow alone (about 150 MB) leave no room for a query
MIN_MEMORY_BYTES = 256 * 1000**2
#: DuckDB threads in the child (each has its own buffers)
THREADS = 4
#: how often the parent looks at the child's resident set
POLL_S = 0.002
#: the child is stopped this far below the limit, so its peak (one poll of growth later) stays under it
MARGIN_FRACTION = 0.08

_UNITS = {
    "": None,
    "b": 1,
    "kb": 1000,
    "mb": 1000**2,
    "gb": 1000**3,
    "tb": 1000**4,
    "kib": 1024,
    "mib": 1024**2,
    "gib": 1024**3,
    "tib": 1024**4,
}
_SIZE = re.compile(r"^\s*([0-9]+(?:\.[0-9]+)?)\s*([a-zA-Z]*)\s*$")


def parse_size(text: str) -> int:
    """``2GB``, ``512MB``, ``1.5GiB`` in bytes (DuckDB's units: KB = 1000, KiB = 1024); ValueError
    with the reason for anything else (a bare number, an unknown unit, less than 256MB)."""
    m = _SIZE.match(text)
    unit = m.group(2).lower() if m else ""
    if not m or unit not in _UNITS:
        raise ValueError(f"invalid size {text!r}; give a number and a unit, e.g. 2GB, 512MB or 1.5GiB")
    factor = _UNITS[unit]
    if factor is None:
        raise ValueError(f"invalid size {text!r}: a unit is needed, e.g. {text.strip()}MB or {text.strip()}GB")
    n = float(m.group(1)) * factor
    if not math.isfinite(n) or n < MIN_MEMORY_BYTES:
        raise ValueError(f"{text.strip()} is too small; at least {MIN_MEMORY_BYTES // 1000**2}MB")
    return int(n)


@dataclass(frozen=True)
class Limits:
    """What one query may use: bytes of resident memory (the whole child process) and seconds of wall time."""

    memory_bytes: int = MIN_MEMORY_BYTES * 8
    timeout_s: float = DEFAULT_TIMEOUT_S
    #: the limit as the user wrote it (for messages)
    memory_text: str = DEFAULT_MEMORY


@dataclass
class Outcome:
    """How the child ended: its exit status as returned, the limit hit (``memory``, ``time`` or None), its peak RSS."""

    status: int
    limit_hit: str | None
    peak_rss: int


def _mb(n: int) -> str:
    return f"{n / 1000**2:.0f}MB"


def _sizes(pid: int) -> tuple[int, int] | None:
    """(address space, resident) bytes of ``pid`` now (Linux /proc); None where they cannot be read."""
    try:
        with open(f"/proc/{pid}/statm", "rb") as fh:
            size, resident = fh.read().split()[:2]
        return int(size) * _PAGE, int(resident) * _PAGE
    except (OSError, ValueError, IndexError):
        return None


#: what the child sends when its query starts: b"R", then its address space then and its cap
_READY = struct.Struct("<cQQ")
#: signals a child dies of when an allocation at its address-space cap fails in code that does not
#: check for it (a native library's allocator or thread start) rather than raising Out of Memory
_ALLOCATION_DEATHS = (signal.SIGSEGV, signal.SIGBUS, signal.SIGABRT)


_PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def _pump(src: Any, dst: TextIO) -> None:
    """Copy the child's bytes to ``dst`` (a text stream) as they come, decoding UTF-8 across reads."""
    dec = codecs.getincrementaldecoder("utf-8")("replace")
    open_ = True
    while True:
        chunk = src.read1(1 << 16) if hasattr(src, "read1") else src.read(1 << 16)
        if not chunk:
            break
        if open_:
            try:
                dst.write(dec.decode(chunk))
            except (OSError, ValueError):  # the reader went away (recap sql ... | head): drain, so the child ends
                open_ = False
    try:
        if open_:
            dst.write(dec.decode(b"", final=True))
            dst.flush()
    except (OSError, ValueError):
        pass


_CHILD_CODE = (
    "import sys; sys.path[:] = [p for p in sys.path if p not in ('', '.')]; sys.path.insert(0, {root!r}); "
    "from reports.sandbox import child_main; sys.exit(child_main({fd}))"
)


def run_limited(job: dict[str, Any], limits: Limits, out: TextIO, err: TextIO) -> Outcome:
    """Run ``job`` (see :func:`child_main`) in a child process under ``limits``, relaying its output to
    ``out`` / ``err``; when a limit is hit the child is killed and one line on ``err`` says which."""
    ready_r, ready_w = os.pipe()
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    try:
        proc = subprocess.Popen(
            [sys.executable, "-c", _CHILD_CODE.format(root=str(ROOT), fd=ready_w)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            pass_fds=(ready_w,),
            env=env,
        )
    finally:
        os.close(ready_w)
    payload = json.dumps({**job, "memory_bytes": limits.memory_bytes, "memory_text": limits.memory_text}).encode()
    threads = [
        threading.Thread(target=_feed, args=(proc.stdin, payload), daemon=True),
        threading.Thread(target=_pump, args=(proc.stdout, out), daemon=True),
        threading.Thread(target=_pump, args=(proc.stderr, err), daemon=True),
    ]
    for t in threads:
        t.start()
    os.set_blocking(ready_r, False)
    watch = _Watch(proc, ready_r, limits)
    try:
        watch.until_exit()
    finally:
        os.close(ready_r)
        if proc.returncode is None:  # interrupted (Ctrl-C): the child goes with us
            proc.kill()
            proc.wait()
    for t in threads[1:]:
        t.join()
    _say_limit(watch, err)
    status = watch.status
    code = 2 if watch.limit_hit or status is None or status < 0 else status
    return Outcome(code, watch.limit_hit, watch.peak)


@dataclass
class _Watch:
    """The parent's watch over the child: polls its resident set every :data:`POLL_S` until it exits,
    starts the clock when the child says its query starts (a byte on ``ready_r``), and kills it the
    first time a limit is passed."""

    proc: subprocess.Popen[bytes]
    ready_r: int
    limits: Limits
    started: float | None = None
    limit_hit: str | None = None
    peak: int = 0
    #: the child's exit status once it has ended
    status: int | None = None
    #: the child's address space at the last poll; at its query's start and the cap it set (0: not said)
    size: int = 0
    start_size: int = 0
    cap: int = 0

    def until_exit(self) -> None:
        """Poll until the child has ended (killed or not)."""
        threshold = self.limits.memory_bytes * (1 - MARGIN_FRACTION)
        while not self._ended():
            sizes = _sizes(self.proc.pid)
            rss = None
            if sizes is not None and sizes[0]:  # a child that has died but is not reaped yet shows zeros
                self.size, rss = sizes
                self.peak = max(self.peak, rss)
            if self.started is None:
                self._note_start()
            if self.limit_hit is None:
                if rss is not None and rss > threshold:
                    self.limit_hit = "memory"
                elif self.started is not None and time.monotonic() - self.started > self.limits.timeout_s:
                    self.limit_hit = "time"
                if self.limit_hit is not None:
                    self.proc.send_signal(signal.SIGKILL)
            time.sleep(POLL_S)
        if self.limit_hit is None and self._died_at_the_cap():
            self.limit_hit = "address space"

    def _ended(self) -> bool:
        """Reap the child if it has ended, keeping its exit status and peak resident set."""
        pid, wstatus, usage = os.wait4(self.proc.pid, os.WNOHANG)
        if not pid:
            return False
        self.status = os.waitstatus_to_exitcode(wstatus)
        self.peak = max(self.peak, int(usage.ru_maxrss) * 1024)
        self.proc.returncode = self.status
        return True

    def _note_start(self) -> None:
        """Start the time limit's clock once the child has said its query starts (with its address
        space then and the cap it set: :func:`child_main`)."""
        try:
            said = os.read(self.ready_r, _READY.size)
        except BlockingIOError:
            return
        if said:
            self.started = time.monotonic()
            if len(said) == _READY.size:
                _, self.start_size, self.cap = _READY.unpack(said)

    def _died_at_the_cap(self) -> bool:
        """The child died of a signal an allocation failing at its address-space cap causes, its
        address space last seen in the upper half of the room the cap gave the query: the memory
        limit, not a crash (seen under load: a cross join's result, SIGSEGV in native code)."""
        if self.status is None or self.status >= 0 or -self.status not in _ALLOCATION_DEATHS or not self.cap:
            return False
        return self.size >= self.start_size + (self.cap - self.start_size) // 2


def _say_limit(watch: _Watch, err: TextIO) -> None:
    """The one line on ``err`` for a child stopped at a limit or killed by a signal (nothing otherwise)."""
    limits, status = watch.limits, watch.status
    if watch.limit_hit == "memory":
        err.write(
            f"recap: error: sql: memory limit {limits.memory_text} hit: the query was stopped at {_mb(watch.peak)} of resident memory; "
            "raise it with --memory-limit, or select fewer rows or smaller values\n"
        )
    elif watch.limit_hit == "time":
        err.write(f"recap: error: sql: time limit {limits.timeout_s:g}s hit: the query was stopped; raise it with --timeout\n")
    elif watch.limit_hit == "address space":
        err.write(
            f"recap: error: sql: memory limit {limits.memory_text} hit: the query process died "
            f"({signal.Signals(-(status or 0)).name}) at its address-space cap ({_mb(watch.size)} mapped); "
            "raise it with --memory-limit, or select fewer rows or smaller values\n"
        )
    elif status is not None and status < 0:
        err.write(f"recap: error: sql: the query process died ({signal.Signals(-status).name}); try a smaller query\n")


def _feed(dst: Any, payload: bytes) -> None:
    try:
        dst.write(payload)
        dst.close()
    except OSError:  # the child died before reading its job
        pass


# -- the child -----------------------------------------------------------------------------------


def _statm() -> tuple[int, int] | None:
    """(address space, resident) bytes of this process (Linux /proc); None where they cannot be read."""
    try:
        with open("/proc/self/statm", "rb") as fh:
            size, resident = fh.read().split()[:2]
        return int(size) * _PAGE, int(resident) * _PAGE
    except (OSError, ValueError):
        return None


def _cap_address_space(memory_bytes: int) -> tuple[int, int]:
    """No new mapping past what the process has now plus the room left under the limit: new memory
    needs new mappings, so one allocation bigger than that room fails at once (DuckDB's Out of Memory
    error, Python's MemoryError) instead of being filled page by page until the parent kills."""
    now = _statm()
    if now is None:
        return 0, 0
    size, resident = now
    room = max(int(memory_bytes * (1 - MARGIN_FRACTION)) - resident, 16 << 20)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    want = size + room
    if hard != resource.RLIM_INFINITY:
        want = min(want, hard)
    resource.setrlimit(resource.RLIMIT_AS, (want, hard))
    return size, want


def child_main(ready_fd: int, argv: Sequence[str] = ()) -> int:
    """The child: read the job (run_dirs, query, format, max_rows, memory_bytes) from stdin, open the runs,
    say ``ready`` on ``ready_fd``, run the query and print its result; 0, or 2 with one line on stderr."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent too; it stops this process
    job = json.loads(sys.stdin.buffer.read())
    memory = int(job["memory_bytes"])
    limit_text = job.get("memory_text", _mb(memory))
    try:
        con, skipped = open_runs_checked(job["run_dirs"], memory_limit=f"{memory // 2 // 1024}KiB", threads=THREADS)
        try:
            size, cap = _cap_address_space(memory)
            os.write(ready_fd, _READY.pack(b"R", size, cap))
            os.close(ready_fd)
            result = run_query(con, job["query"])
        finally:
            con.close()
        for s in skipped:
            print(f"warning: {s.line()}", file=sys.stderr)
        print_result(result, job["format"], int(job["max_rows"]), sys.stdout)
        sys.stdout.flush()
    except ReportError as exc:
        text = str(exc)
        if "Out of Memory Error" in text or "bad_alloc" in text:
            found = re.search(r"Out of Memory Error: [^()]*(\([^()]*\))?", text)
            detail = found.group(0).strip() if found else "Out of Memory Error"
            print(
                f"recap: error: sql: memory limit {limit_text} hit ({detail}); "
                "raise it with --memory-limit, or select fewer rows or smaller values",
                file=sys.stderr,
            )
        else:
            print(f"recap: error: sql: {text}", file=sys.stderr)
        return 2
    except MemoryError:
        print(
            f"recap: error: sql: memory limit {limit_text} hit while building the result; raise it with --memory-limit, "
            "or select fewer rows or smaller values",
            file=sys.stderr,
        )
        return 2
    except Exception as exc:  # noqa: BLE001 - one line, never a traceback
        print(" ".join(f"recap: error: sql: {type(exc).__name__}: {exc}".split())[:500], file=sys.stderr)
        return 2
    return 0
