"""The local sandbox: a temporary folder and a process group on the host. It is NOT isolation.

For machines without Docker, asked for by name (``sandbox: local``). The repository is cloned at
``base_commit`` into a temporary root; each command is ``bash -c`` in a new session with a
scrubbed environment (``PATH``, ``LANG``, a temporary ``HOME`` and ``TMPDIR``, and ``spec.env``:
no host variable such as an API key). What binds, where the host allows it:

* ``unshare --pid --fork --mount-proc`` (and ``--net`` unless ``limits.network``): the command is
  PID 1 of its own pid namespace, so when it ends or is killed every process it started dies with
  it (daemons included), and without network it sees only a loopback that is down;
* a pids cgroup (``/sys/fs/cgroup/pids``, when writable) with ``pids.max = limits.pids``: a fork
  bomb stops there, even as root (``RLIMIT_NPROC`` does not bind root; it is set too);
* ``RLIMIT_AS`` (memory per process) and ``RLIMIT_FSIZE`` (any single file) from the limits; the
  repository folder's size is measured after each command.

What does not: the commands run as the worker's user on the host's file system; they can read
and write anything that user can (``rm -rf /`` would be the host's). :attr:`LocalSandbox.warning`
says so, and :attr:`LocalSandbox.confinement` lists what was actually applied.
"""

from __future__ import annotations

import os
import resource
import secrets
import shutil
import signal
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from workers.sandbox import registry
from workers.sandbox.base import CommandResult, Sandbox, SandboxError, SandboxKind, SandboxSpec
from workers.sandbox.repo_copy import clone_at

WARNING = (
    "the local sandbox is NOT isolation: commands run on the host as this user and can read, "
    "change or delete anything it can; use `sandbox: docker` for untrusted commands"
)
PIDS_CGROUP_ROOT = Path("/sys/fs/cgroup/pids")
_UNSHARE_PROBE: dict[tuple[str, ...], bool] = {}


def _unshare_works(flags: tuple[str, ...]) -> bool:
    if flags not in _UNSHARE_PROBE:
        ok = False
        if shutil.which("unshare"):
            try:
                ok = subprocess.run(["unshare", *flags, "true"], capture_output=True, timeout=10).returncode == 0
            except (OSError, subprocess.TimeoutExpired):
                ok = False
        _UNSHARE_PROBE[flags] = ok
    return _UNSHARE_PROBE[flags]


def dir_bytes(root: Path) -> int:
    """Bytes of the regular files under ``root`` (links not followed), like ``du -sb`` roughly."""
    total = 0
    for dirpath, _dirs, files in os.walk(root):
        for name in files:
            try:
                total += os.lstat(os.path.join(dirpath, name)).st_size
            except OSError:
                pass
    return total


def kill_cgroup(cgroup: str | None) -> None:
    """Kill every process in a pids cgroup and remove it (no error when it is gone)."""
    if not cgroup:
        return
    procs = Path(cgroup) / "cgroup.procs"
    for _ in range(50):
        try:
            pids = [int(x) for x in procs.read_text().split()]
        except OSError:
            return
        if not pids:
            break
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.02)
    try:
        os.rmdir(cgroup)
    except OSError:
        pass


class LocalSandbox(Sandbox):
    """A temporary clone and a process group per command; NOT isolation (see :data:`WARNING`)."""

    kind: SandboxKind = "local"
    warning: str = WARNING

    def __init__(self, spec: SandboxSpec) -> None:
        self.spec = spec
        self.limits = spec.limits
        self.id = f"local-{secrets.token_hex(6)}"
        self._closed = False
        self._lock = threading.Lock()
        if spec.repo_path is None:  # the repository is inside a Docker image: nothing to clone here
            raise SandboxError("this repository is inside a Docker image (repo_path None): only a docker sandbox can open it")
        self.root = Path(tempfile.mkdtemp(prefix="recap-sandbox-local-"))
        self.repo = self.root / spec.workdir.strip("/")
        self.workdir = str(self.repo)
        self.home = self.root / "home"
        self._cgroup: str | None = None
        self._register(None)
        try:
            self.home.mkdir()
            (self.root / "tmp").mkdir()
            self.base_commit = clone_at(spec.repo_path, spec.base_commit, self.repo)
            self._cgroup = self._make_cgroup()
            self._register(None)
        except BaseException:
            self.close()
            raise
        lim = spec.limits
        flags = ("--pid", "--fork", "--mount-proc", "--kill-child") + (() if lim.network else ("--net",))
        self._prefix: list[str] = ["unshare", *flags] if _unshare_works(flags) else []
        self.confinement: tuple[str, ...] = tuple(
            x
            for x, on in (
                ("pid-namespace", bool(self._prefix)),
                ("no-network", bool(self._prefix) and not lim.network),
                ("pids-cgroup", self._cgroup is not None),
                ("rlimits", True),
            )
            if on
        )
        (self.home / ".gitconfig").write_text(
            "[user]\n\tname = recap-eval sandbox\n\temail = sandbox@recap-eval.invalid\n[safe]\n\tdirectory = *\n"
        )
        self.env = {
            "PATH": os.environ.get("PATH", "/usr/local/bin:/usr/bin:/bin"),
            "HOME": str(self.home),
            "LANG": "C.UTF-8",
            "TMPDIR": str(self.root / "tmp"),
            **spec.env,
        }

    # -- bookkeeping -------------------------------------------------------------------

    def _register(self, pgid: int | None) -> None:
        registry.write_entry(
            self.id,
            {"labels": dict(self.spec.labels), "root": str(self.root), "cgroup": self._cgroup, "pgid": pgid},
        )

    def _make_cgroup(self) -> str | None:
        if not os.access(PIDS_CGROUP_ROOT, os.W_OK):
            return None
        p = PIDS_CGROUP_ROOT / f"recap-eval-{self.id}"
        try:
            p.mkdir()
            (p / "pids.max").write_text(str(self.limits.pids))
        except OSError:
            try:
                p.rmdir()
            except OSError:
                pass
            return None
        return str(p)

    def _preexec(self) -> None:  # runs in the child between fork and exec
        lim = self.limits
        if self._cgroup:
            with open(os.path.join(self._cgroup, "cgroup.procs"), "w") as f:
                f.write(str(os.getpid()))
        for res, value in (
            (resource.RLIMIT_AS, lim.memory_bytes),
            (resource.RLIMIT_FSIZE, lim.disk_bytes),
            (resource.RLIMIT_NPROC, lim.pids),
        ):
            try:
                resource.setrlimit(res, (value, value))
            except (ValueError, OSError):
                pass

    # -- commands ----------------------------------------------------------------------

    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        """Run ``command`` with ``bash -c`` in the repository folder; on timeout the command's
        process group (and pid namespace) is killed."""
        if self._closed:
            raise SandboxError("the sandbox is closed")
        lim = self.limits
        tmo = float(timeout_s if timeout_s is not None else lim.command_timeout_s)
        cap = lim.output_bytes
        with self._lock:
            t0 = time.monotonic()
            proc = subprocess.Popen(
                [*self._prefix, "bash", "-c", command],
                cwd=self.repo,
                env=self.env,
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                preexec_fn=self._preexec,
            )
            self._register(proc.pid)
            kept = bytearray()
            seen = [0]

            def read() -> None:
                assert proc.stdout is not None
                try:
                    while chunk := os.read(proc.stdout.fileno(), 65536):
                        seen[0] += len(chunk)
                        if len(kept) < cap:
                            kept.extend(chunk[: cap - len(kept)])
                except (OSError, ValueError):  # the pipe was closed under us (a stray held it)
                    pass

            reader = threading.Thread(target=read, daemon=True)
            reader.start()
            timed_out = False
            try:
                rc = proc.wait(timeout=tmo)
            except subprocess.TimeoutExpired:
                timed_out = True
            self._kill_group(proc.pid)
            if timed_out:
                rc = proc.wait()
            kill_cgroup_procs(self._cgroup)
            reader.join(timeout=5)
            if reader.is_alive() and proc.stdout is not None:  # a stray outside the group holds the pipe
                proc.stdout.close()
            duration = time.monotonic() - t0
            self._register(None)
        exit_code: int | None = None if timed_out else (rc if rc >= 0 else 128 - rc)
        output = bytes(kept).decode("utf-8", errors="replace")
        used = dir_bytes(self.repo)
        if used > lim.disk_bytes:
            exit_code = None
            output += f"\n[sandbox: the repository folder is {used} bytes, over the {lim.disk_bytes}-byte disk limit]"
        return CommandResult(exit_code, output, seen[0], duration, timed_out=timed_out, truncated=seen[0] > cap)

    @staticmethod
    def _kill_group(pgid: int) -> None:
        try:
            os.killpg(pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass

    # -- files ---------------------------------------------------------------------------

    def _path(self, path: str) -> Path:
        return self.repo / path  # an absolute path replaces the base: it is the host's (not isolation)

    def read_file(self, path: str) -> bytes:
        """A file's bytes; relative paths are under the repository folder."""
        return self._path(path).read_bytes()

    def write_file(self, path: str, data: bytes) -> None:
        """Create or replace a file (its folders created)."""
        p = self._path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)

    def close(self) -> None:
        """Kill what is left, remove the temporary root and the cgroup; safe to call twice."""
        self._closed = True
        kill_cgroup(self._cgroup)
        shutil.rmtree(self.root, ignore_errors=True)
        registry.remove_entry(self.id)


def kill_cgroup_procs(cgroup: str | None) -> None:
    """Kill what is left in a sandbox's pids cgroup after a command (a stray that left the group)."""
    if not cgroup:
        return
    try:
        pids = [int(x) for x in (Path(cgroup) / "cgroup.procs").read_text().split()]
    except OSError:
        return
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
