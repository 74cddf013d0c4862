"""The sandbox interface: run a model's commands against one repository copy, under limits.

A coding episode (``benchmark: swe``) owns one :class:`Sandbox` for its lifetime: the repository
at its base commit in ``workdir``, commands run through ``bash`` there with a timeout and an output
cap, files read and written by path. Two kinds implement it:

* ``docker``: a container of a locally built image (no registry is needed), no network by default,
  memory/pids/disk limits, no host environment variable inside (so no API key is visible);
* ``local``: a process sandbox in a temporary folder for machines without Docker. It is *not*
  isolation (the commands run on the host as the worker's user), so a sweep must ask for it by
  name (``sandbox: local``).

Everything a sandbox starts carries labels (:data:`LABEL_RUN`, :data:`LABEL_EPISODE`,
:data:`LABEL_WORKER`) so a driver can remove what a killed worker left behind
(:func:`workers.sandbox.remove_labelled`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Literal

from recap.env import EnvError
from schemas.labels import SANDBOX_INFRA_KIND

SandboxKind = Literal["docker", "local"]
SANDBOX_KINDS: tuple[SandboxKind, ...] = ("docker", "local")

#: the Ray node resource that bounds sandboxes per node (``ray.sandboxes_per_node``): a node
#: declaring N runs at most N episode workers of a coding sweep
NODE_RESOURCE = "recap_sandbox"

#: labels on every container/process group a sandbox starts (the cleanup keys)
LABEL_RUN = "recap-eval.run"
LABEL_EPISODE = "recap-eval.episode"
LABEL_WORKER = "recap-eval.worker"


class SandboxError(RuntimeError):
    """The sandbox itself failed (Docker unreachable, image missing, container gone); a model's
    failing command is never a SandboxError.

    ``service``: the container service failed (the daemon unreachable or erroring, a container
    that could not start or is gone) - infrastructure, which may work on another try; False: the
    sandbox cannot work for this instance (an image missing or at the wrong commit, a repository
    that is not one), which would fail the same way again. :func:`episode_failure` turns either
    into what the episode ends with."""

    def __init__(self, message: str, *, service: bool = False) -> None:
        super().__init__(message)
        self.service = service


class OutsideRepository(PermissionError):
    """A path that leaves the sandbox's repository once every symlink in it is resolved.

    The file operations of a sandbox (:meth:`Sandbox.read_file`, :meth:`Sandbox.read_lines`,
    :meth:`Sandbox.write_file`) resolve a path *inside* the sandbox, every component including the
    last (a dangling final link resolved to where a write would land); a committed link to
    ``/etc/passwd`` or a folder linked to ``/`` is refused with this, never followed (issue 35
    item 2). A PermissionError, so code that refuses unreadable files refuses these too."""


class FileTooLarge(OSError):
    """A file bigger than the ``max_bytes`` a read allowed; nothing of it was read (issue 35 item 4:
    a tool's reads stay bounded in the worker)."""

    def __init__(self, path: str, size: int, limit: int) -> None:
        super().__init__(f"{path} is {size} bytes, over the {limit}-byte limit of this read")
        self.path = path
        self.size = size
        self.limit = limit


@dataclass(frozen=True)
class FileSlice:
    """Lines of a file as :meth:`Sandbox.read_lines` returns them, read in the sandbox: only
    ``data`` crosses into the worker, never the rest of the file."""

    #: lines first..last (1-based, inclusive), joined with their newlines, cut to max_bytes
    data: bytes
    #: lines in the whole file (a final newline ends the last line, adds none)
    total_lines: int
    #: the file's size
    total_bytes: int
    #: data was cut at max_bytes
    truncated: bool


class SandboxUnavailable(EnvError):
    """The episode's sandbox service failed (:attr:`SandboxError.service`): the row's error starts
    with ``sandbox:``, which the pipeline reads as infrastructure (``infra_error``, run again by
    the next resume) instead of a 0 % outcome of the agent."""

    kind = SANDBOX_INFRA_KIND

    def __init__(self, message: str) -> None:
        super().__init__(f"{SANDBOX_INFRA_KIND}: {message}")


def episode_failure(instance_id: str, what: str, exc: SandboxError) -> EnvError:
    """What an environment raises for a sandbox failure during an episode: a
    :class:`SandboxUnavailable` when the service failed, else an ``env_error`` outcome."""
    cls = SandboxUnavailable if exc.service else EnvError
    return cls(f"{instance_id}: {what}: {exc}")


@dataclass(frozen=True)
class SandboxLimits:
    """What one episode's sandbox may use. The output cap is stated to the model in the tool's
    description, so a cut output is never a surprise."""

    #: one command's wall time; a command that runs longer is killed (its process group)
    command_timeout_s: float = 60.0
    #: bytes of one command's output the model sees (the rest is cut, and the cut is said)
    output_bytes: int = 10_000
    #: commands per episode
    max_commands: int = 250
    #: the whole episode's command time
    wall_time_s: float = 3600.0
    #: bytes the repository folder may grow to
    disk_bytes: int = 1 << 30
    #: bytes each scratch folder a program may write to (``/tmp``, ``/var/tmp``, ``$HOME``) may
    #: hold (issue 35 item 3: every writable place is bounded, not only the repository)
    scratch_bytes: int = 256 << 20
    memory_bytes: int = 2 << 30
    #: processes at once (a fork bomb stops here)
    pids: int = 256
    #: network inside the sandbox (off unless the sweep turns it on)
    network: bool = False


@dataclass(frozen=True)
class CommandResult:
    """One command's outcome. ``exit_code`` is None when the command was killed (timeout, limit);
    ``output`` is stdout and stderr interleaved, cut to the output cap; ``output_bytes`` is its
    size before the cut."""

    exit_code: int | None
    output: str
    output_bytes: int
    duration_s: float
    timed_out: bool = False
    truncated: bool = False


@dataclass(frozen=True)
class SandboxSpec:
    """What to open: the repository (a local git repository checked out at ``base_commit``),
    the image (docker), the limits, extra environment variables (never the host's own), and the
    labels to put on everything started. ``repo_path`` None: the image itself holds the
    repository at ``workdir``, at ``base_commit`` (the SWE-bench harness's per-instance images,
    ``/testbed``); nothing is copied in, and only a docker sandbox can open it."""

    repo_path: str | None
    base_commit: str
    image: str = "recap-eval/sandbox:py311"
    limits: SandboxLimits = field(default_factory=SandboxLimits)
    env: Mapping[str, str] = field(default_factory=dict)
    labels: Mapping[str, str] = field(default_factory=dict)
    #: where the repository sits inside the sandbox (docker) or under its temporary root (local)
    workdir: str = "/repo"


class Sandbox(ABC):
    """One repository copy where commands run under :class:`SandboxLimits`."""

    kind: SandboxKind
    #: the repository's folder as commands see it (their working directory)
    workdir: str

    @abstractmethod
    def run(self, command: str, *, timeout_s: float | None = None) -> CommandResult:
        """Run ``command`` with ``bash -c`` in ``workdir`` (timeout: the limit's unless given)."""

    @abstractmethod
    def read_file(self, path: str, *, max_bytes: int | None = None) -> bytes:
        """A file's bytes; ``path`` relative to ``workdir`` or absolute inside the sandbox, resolved
        inside the sandbox (every symbolic link in it, the last included). Raises
        :class:`OutsideRepository` when it leaves the repository, FileNotFoundError /
        IsADirectoryError like the OS, :class:`FileTooLarge` (nothing read) when the file is
        bigger than ``max_bytes``."""

    @abstractmethod
    def read_lines(self, path: str, first: int, last: int | None, max_bytes: int) -> FileSlice:
        """Lines ``first``..``last`` (1-based, inclusive; ``last`` None: to the end) of a file,
        cut to ``max_bytes``, with the file's line count and size. Bounded: only what it returns
        is read into the worker (the counting happens in the sandbox). Paths and errors as
        :meth:`read_file`."""

    @abstractmethod
    def write_file(self, path: str, data: bytes) -> None:
        """Create or replace a file (its folder is created); the path is resolved as for
        :meth:`read_file` (:class:`OutsideRepository` when it, or a link on the way, leaves the
        repository) and written at the resolved place."""

    @abstractmethod
    def close(self) -> None:
        """Stop and remove everything this sandbox started; safe to call twice."""

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` ran (implementations set ``_closed``)."""
        return bool(getattr(self, "_closed", False))

    def __enter__(self) -> Sandbox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
