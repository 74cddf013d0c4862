"""A test-only process sandbox: a temporary clone of the repository, commands through ``bash -c``.

It implements :class:`workers.sandbox.base.Sandbox` with the least the SWE environment's tests need
(a timeout that kills the command's process group, an output cap), so they run before the real
sandboxes (``workers.sandbox.open_sandbox``) exist; no isolation at all.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from workers.sandbox.base import CommandResult, Sandbox, SandboxError, SandboxKind, SandboxSpec


class TmpSandbox(Sandbox):
    kind: SandboxKind = "local"

    def __init__(self, spec: SandboxSpec) -> None:
        self.spec = spec
        self.root = Path(tempfile.mkdtemp(prefix="swe-test-sandbox-"))
        self.workdir = str(self.root / "repo")
        clone = subprocess.run(["git", "clone", "-q", spec.repo_path, self.workdir], capture_output=True, text=True)
        if clone.returncode != 0:
            shutil.rmtree(self.root, ignore_errors=True)
            raise SandboxError(f"git clone failed: {clone.stderr.strip()}")
        checkout = subprocess.run(
            ["git", "-c", "advice.detachedHead=false", "checkout", "-q", spec.base_commit],
            cwd=self.workdir,
            capture_output=True,
            text=True,
        )
        if checkout.returncode != 0:
            shutil.rmtree(self.root, ignore_errors=True)
            raise SandboxError(f"git checkout failed: {checkout.stderr.strip()}")
        self.env = {
            "PATH": f"{Path(sys.executable).parent}:/usr/local/bin:/usr/bin:/bin",
            "HOME": str(self.root),
            "LANG": "C.UTF-8",
            "PYTHONDONTWRITEBYTECODE": "1",
            "GIT_AUTHOR_NAME": "sandbox",
            "GIT_AUTHOR_EMAIL": "sandbox@example.invalid",
            "GIT_COMMITTER_NAME": "sandbox",
            "GIT_COMMITTER_EMAIL": "sandbox@example.invalid",
            **spec.env,
        }
        self.closed = False
        self.commands: list[str] = []

    def _path(self, path: str) -> Path:
        return Path(path) if os.path.isabs(path) else Path(self.workdir) / path

    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        if self.closed:
            raise SandboxError("the sandbox is closed")
        self.commands.append(command)
        limit = self.spec.limits.command_timeout_s if timeout_s is None else timeout_s
        started = time.monotonic()
        proc = subprocess.Popen(
            ["bash", "-c", command],
            cwd=self.workdir,
            env=self.env,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        timed_out = False
        try:
            out, _ = proc.communicate(timeout=limit)
        except subprocess.TimeoutExpired:
            timed_out = True
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
        cap = self.spec.limits.output_bytes
        return CommandResult(
            exit_code=None if timed_out else proc.returncode,
            output=out[:cap].decode("utf-8", errors="replace"),
            output_bytes=len(out),
            duration_s=time.monotonic() - started,
            timed_out=timed_out,
            truncated=len(out) > cap,
        )

    def read_file(self, path: str) -> bytes:
        return self._path(path).read_bytes()

    def write_file(self, path: str, data: bytes) -> None:
        p = self._path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(data)

    def close(self) -> None:
        if not self.closed:
            self.closed = True
            shutil.rmtree(self.root, ignore_errors=True)


class SandboxLog:
    """A factory that opens :class:`TmpSandbox` es and keeps them (so a test can see what ran and
    that each was closed)."""

    def __init__(self) -> None:
        self.opened: list[TmpSandbox] = []
        self.specs: list[SandboxSpec] = []

    def __call__(self, spec: SandboxSpec) -> TmpSandbox:
        box = TmpSandbox(spec)
        self.opened.append(box)
        self.specs.append(spec)
        return box
