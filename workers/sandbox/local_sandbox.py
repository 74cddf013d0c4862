"""The local sandbox: a repository copy on the host, each command confined by bubblewrap.

For machines without Docker, asked for by name (``sandbox: local``). The repository is cloned at
``base_commit`` into a temporary root; each command is ``bash -c`` with a scrubbed environment
(``PATH``, ``LANG``, ``HOME``, ``TMPDIR`` and ``spec.env``: no host variable such as an API key).

Confinement (issue 35 item 1; :mod:`workers.sandbox.bwrap`): each command runs under bubblewrap
with every namespace new (the network too unless ``limits.network``), every capability dropped,
a fresh ``/proc``, a minimal ``/dev``, the host's system folders read-only, and as the only
writable places the sandbox's own folders: the repository at ``spec.workdir`` (``/repo``, as in a
container), ``/tmp``, ``/var/tmp`` and ``$HOME``. So ``umount``, ``mount``, ``chroot``,
``nsenter`` into a host namespace, ptrace of a host process and reading another process's
``/proc/<pid>/environ`` all fail: the host's processes are not in the command's world.

Where bubblewrap is missing or does not work, the sandbox is refused (:class:`SandboxError`
naming the fix) unless the sweep says ``sandbox_trust: none``: then the former, weaker confinement
runs (``unshare --pid --fork --mount-proc`` and ``--net``, which a root command can undo; the
commands see and can change the host's files as the worker's user), and :attr:`LocalSandbox.warning`
says so. Kept in both: a pids cgroup (``/sys/fs/cgroup/pids``, when writable: a fork bomb stops at
``limits.pids``, even as root), ``RLIMIT_AS``/``RLIMIT_FSIZE``/``RLIMIT_NPROC``, the timeout
(process group and pid namespace killed), the output cap, the registry entry for cleanup.

Disk (issue 35 item 3; :mod:`workers.sandbox.disk_bound`): the repository, ``/tmp``,
``/var/tmp`` and ``$HOME`` are folders of one root, bounded as a whole: a size-limited tmpfs
where the worker can mount one, else a watchdog; measured after each command and reported.

Files (items 2 and 4; :mod:`workers.sandbox.repo_paths`): the worker reads and writes the host's
copy, so every path is resolved as the sandbox sees it, symlinks included, and refused
(:class:`OutsideRepository`) when any component leaves the repository; reads are bounded.
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
from typing import Literal

from workers.sandbox import bwrap, disk_bound, registry, repo_paths
from workers.sandbox.base import CommandResult, FileSlice, Sandbox, SandboxError, SandboxKind, SandboxSpec
from workers.sandbox.repo_copy import clone_at

#: ``sandbox_trust``: ``isolated`` (default): a local sandbox confines its commands with
#: bubblewrap or is refused; ``none``: the sweep accepts commands that are not isolated
SandboxTrust = Literal["isolated", "none"]
TRUST_LEVELS: tuple[SandboxTrust, ...] = ("isolated", "none")
#: the trust a sandbox gets when none is given (the test suite's RECAP_SKIP_BWRAP=1 sets ``none``,
#: tests/conftest.py; nothing else changes it)
DEFAULT_TRUST: SandboxTrust = "isolated"

WARNING_BWRAP = (
    "the local sandbox confines commands with bubblewrap (new namespaces, no capabilities, the host's "
    "system folders read-only, only the sandbox's own folders writable); it shares the host's kernel, "
    "so `sandbox: docker` remains the stronger choice"
)
WARNING = (
    "the local sandbox is NOT isolation here (sandbox_trust: none, no working bubblewrap): commands run "
    "on the host as this user and can read, change or delete anything it can; use `sandbox: docker` "
    "or install bubblewrap for untrusted commands"
)
PIDS_CGROUP_ROOT = Path("/sys/fs/cgroup/pids")
#: the sandbox's home folder as its commands see it (under bubblewrap)
HOME_INSIDE = "/home/sandbox"
#: seconds between two looks of the disk watchdog (no tmpfs bound)
WATCH_EVERY_S = 0.25
_UNSHARE_PROBE: dict[tuple[str, ...], bool] = {}


def refusal(trust: str | None = None) -> str | None:
    """Why a local sandbox cannot open under ``trust`` (None: :data:`DEFAULT_TRUST`; the answer
    None: it can): bubblewrap does not work here and the sweep did not say ``sandbox_trust: none``.
    One line, naming both fixes."""
    if (trust or DEFAULT_TRUST) == "none":
        return None
    why = bwrap.probe()
    if why is None:
        return None
    return (
        f"sandbox: local confines the model's commands with bubblewrap, and {why}: install it "
        "(apt-get install bubblewrap) or set the swe option sandbox_trust: none to run them unconfined on this host"
    )


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
    return disk_bound.tree_usage(root)[0]


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


def remove_root(root: str | Path) -> None:
    """Remove a local sandbox's temporary root: unmount its tmpfs (when it is one), then the folder."""
    p = Path(root)
    disk_bound.unmount(p)
    shutil.rmtree(p, ignore_errors=True)


class LocalSandbox(Sandbox):
    """A temporary clone, each command under bubblewrap (see the module docstring); with
    ``trust="none"`` and no working bubblewrap, NOT isolation (see :data:`WARNING`)."""

    kind: SandboxKind = "local"

    def __init__(self, spec: SandboxSpec, *, trust: SandboxTrust | str | None = None) -> None:
        trust = trust or DEFAULT_TRUST
        if trust not in TRUST_LEVELS:
            raise SandboxError(f"sandbox_trust must be one of {', '.join(TRUST_LEVELS)}, got {trust!r}")
        if spec.repo_path is None:  # the repository is inside a Docker image: nothing to clone here
            raise SandboxError("this repository is inside a Docker image (repo_path None): only a docker sandbox can open it")
        refused = refusal(trust)
        if refused is not None:
            raise SandboxError(refused)
        wd = os.path.normpath(spec.workdir)
        taken = ("/proc", "/dev", "/tmp", "/var/tmp", HOME_INSIDE, *bwrap.SYSTEM_DIRS)
        if not wd.startswith("/") or wd == "/" or any(wd == t or wd.startswith(t + "/") or t.startswith(wd + "/") for t in taken):
            raise SandboxError(f"a local sandbox's workdir must be a folder of its own (like /repo), got {spec.workdir!r}")
        self.spec = spec
        self.limits = spec.limits
        self.trust = trust
        self.id = f"local-{secrets.token_hex(6)}"
        self._closed = False
        self._lock = threading.Lock()
        self.bwrap = bwrap.probe() is None
        self.warning = WARNING_BWRAP if self.bwrap else WARNING
        lim = spec.limits
        self.root = Path(tempfile.mkdtemp(prefix="recap-sandbox-local-"))
        self._cgroup: str | None = None
        self._register(None)
        try:
            self.tmpfs = disk_bound.can_mount() and disk_bound.mount_tmpfs(
                self.root, disk_bound.tmpfs_size(lim.disk_bytes), disk_bound.tmpfs_inodes(lim.disk_bytes)
            )
            self.repo = self.root / "repo"
            self.home = self.root / "home"
            self.tmp = self.root / "tmp"
            self.var_tmp = self.root / "vartmp"
            for d in (self.home, self.tmp, self.var_tmp):
                d.mkdir()
            self.base_commit = clone_at(spec.repo_path, spec.base_commit, self.repo)
            self._cgroup = self._make_cgroup()
            self._register(None)
            (self.home / ".gitconfig").write_text(
                "[user]\n\tname = recap-eval sandbox\n\temail = sandbox@recap-eval.invalid\n[safe]\n\tdirectory = *\n"
            )
        except BaseException:
            self.close()
            raise
        host_path = os.environ.get("PATH", "/usr/local/bin:/usr/bin:/bin")
        if self.bwrap:
            self.workdir = spec.workdir
            home, tmp = HOME_INSIDE, "/tmp"
            self._binds = bwrap.system_binds(host_path.split(":"))
            self._prefix: list[str] = []
        else:
            self.workdir = str(self.repo)
            home, tmp = str(self.home), str(self.tmp)
            flags = ("--pid", "--fork", "--mount-proc", "--kill-child") + (() if lim.network else ("--net",))
            self._prefix = ["unshare", *flags] if _unshare_works(flags) else []
        self.env = {"PATH": host_path, "HOME": home, "LANG": "C.UTF-8", "TMPDIR": tmp, **spec.env}
        isolated = self.bwrap or bool(self._prefix)
        #: (bytes, entries) of the root after the last command, where no tmpfs bounds it: the
        #: watchdog's first reference (:meth:`_watch_disk`)
        self._tree = disk_bound.tree_usage(self.root) if not self.tmpfs else (disk_bound.used_bytes(self.root, True), 0)
        self._used = self._tree[0]
        self.confinement: tuple[str, ...] = tuple(
            x
            for x, on in (
                ("bwrap", self.bwrap),
                ("pid-namespace", isolated),
                ("no-network", isolated and not lim.network),
                ("pids-cgroup", self._cgroup is not None),
                ("rlimits", True),
                ("disk-tmpfs", self.tmpfs),
            )
            if on
        )

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
            # no single file past what is left of the limit (as measured after the last command)
            (resource.RLIMIT_FSIZE, max(lim.disk_bytes - self._used, 1 << 16)),
            (resource.RLIMIT_NPROC, lim.pids),
        ):
            try:
                resource.setrlimit(res, (value, value))
            except (ValueError, OSError):
                pass

    def argv(self, command: str) -> list[str]:
        """What runs one command: bubblewrap's argv, or the unconfined fallback's."""
        if self.bwrap:
            return bwrap.command_argv(
                command,
                binds=self._binds,
                writable={self.workdir: self.repo, "/tmp": self.tmp, "/var/tmp": self.var_tmp, HOME_INSIDE: self.home},
                workdir=self.workdir,
                env=self.env,
                network=self.limits.network,
            )
        return [*self._prefix, "bash", "-c", command]

    # -- commands ----------------------------------------------------------------------

    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        """Run ``command`` with ``bash -c`` in the repository folder; on timeout (or a disk
        overrun the watchdog sees) the command's process group and pid namespace are killed."""
        if self._closed:
            raise SandboxError("the sandbox is closed")
        lim = self.limits
        tmo = float(timeout_s if timeout_s is not None else lim.command_timeout_s)
        cap = lim.output_bytes
        with self._lock:
            t0 = time.monotonic()
            proc = subprocess.Popen(
                self.argv(command),
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
            over: list[str] = []
            stop = threading.Event()
            watcher = None
            if not self.tmpfs:  # no kernel bound on the root: look at it while the command runs
                watcher = threading.Thread(target=self._watch_disk, args=(proc.pid, stop, over), daemon=True)
                watcher.start()
            timed_out = False
            try:
                rc = proc.wait(timeout=tmo)
            except subprocess.TimeoutExpired:
                timed_out = not over
            stop.set()
            self._kill_group(proc.pid)
            rc = proc.wait()
            if watcher is not None:
                watcher.join(timeout=5)
            kill_cgroup_procs(self._cgroup)
            reader.join(timeout=5)
            if reader.is_alive() and proc.stdout is not None:  # a stray outside the group holds the pipe
                proc.stdout.close()
            duration = time.monotonic() - t0
            self._register(None)
        exit_code: int | None = None if timed_out or over else (rc if rc >= 0 else 128 - rc)
        output = bytes(kept).decode("utf-8", errors="replace")
        if self.tmpfs:
            used = self._used = disk_bound.used_bytes(self.root, True)
        else:
            self._tree = disk_bound.tree_usage(self.root)
            used = self._used = self._tree[0]
        if over or used > lim.disk_bytes:
            exit_code = None
            what = over[0] if over else f"{used} bytes"
            output += (
                f"\n[sandbox: the sandbox's files (repository, /tmp, /var/tmp, $HOME) are {what}, "
                f"over the {lim.disk_bytes}-byte disk limit]"
            )
        return CommandResult(exit_code, output, seen[0], duration, timed_out=timed_out, truncated=seen[0] > cap)

    def _watch_disk(self, pgid: int, stop: threading.Event, over: list[str]) -> None:
        """Kill the command when the root holds more than the disk limit in bytes, or more
        entries than a tmpfs of that size would allow, and it grew since the last look (the
        first look: since the last command ended).

        Why "grew": a sandbox left over the limit (what a command wrote between two looks got
        through before it was stopped) must still take the command that cleans it up; an
        ``rm -rf`` of many files outlasts a look and, judged by the level alone, was killed
        every time - the sandbox could not be brought back under its limit. A command that
        writes while the sandbox is over is still stopped at the next look."""
        lim = self.limits.disk_bytes
        most = disk_bound.tmpfs_inodes(lim)
        before_used, before_entries = self._tree
        while not stop.wait(WATCH_EVERY_S):
            used, entries = disk_bound.tree_usage(self.root)
            grew = used > before_used or entries > before_entries
            if grew and (used > lim or entries > most):
                over.append(f"{used} bytes" if used > lim else f"{used} bytes in {entries} files and folders (at most {most})")
                self._kill_group(pgid)
                kill_cgroup_procs(self._cgroup)
                return
            before_used, before_entries = used, entries

    @staticmethod
    def _kill_group(pgid: int) -> None:
        try:
            os.killpg(pgid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass

    # -- files ---------------------------------------------------------------------------

    def _path(self, path: str) -> Path:
        """The host path of ``path`` as the sandbox sees it; OutsideRepository when it leaves
        the repository (symlinks resolved inside the sandbox's view)."""
        if self._closed:
            raise SandboxError("the sandbox is closed")
        return repo_paths.resolve(self.workdir, self.repo, path)

    def read_file(self, path: str, *, max_bytes: int | None = None) -> bytes:
        """A file's bytes; FileTooLarge (nothing read) when it is bigger than ``max_bytes``."""
        return repo_paths.read_bounded(self._path(path), path, max_bytes)

    def read_lines(self, path: str, first: int, last: int | None, max_bytes: int) -> FileSlice:
        """Lines ``first``..``last`` of a file (bounded memory: :func:`repo_paths.read_lines`)."""
        return repo_paths.read_lines(self._path(path), path, first, last, max_bytes)

    def write_file(self, path: str, data: bytes) -> None:
        """Create or replace a file (its folders created); the file's size is bounded by the
        disk limit like a command's write."""
        p = self._path(path)
        if len(data) > self.limits.disk_bytes:
            raise OSError(27, f"{path}: {len(data)} bytes is over the {self.limits.disk_bytes}-byte disk limit")
        p.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(p, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644)
        with os.fdopen(fd, "wb") as f:
            f.write(data)

    def close(self) -> None:
        """Kill what is left, remove the temporary root (its tmpfs unmounted) and the cgroup; safe to call twice."""
        self._closed = True
        kill_cgroup(getattr(self, "_cgroup", None))
        remove_root(self.root)
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
