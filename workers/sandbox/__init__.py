"""Sandboxes for coding environments: one isolated copy of a repository per episode, where a
model's shell commands run under limits (see :mod:`workers.sandbox.base`).

:func:`open_sandbox` is the one entry point: it checks what can be checked before anything starts
(the kind, the repository and its base commit, the daemon, the image) and says what is wrong in
one line (:class:`SandboxError`).
"""

from __future__ import annotations

from workers.sandbox.base import (
    LABEL_EPISODE,
    LABEL_RUN,
    LABEL_WORKER,
    SANDBOX_KINDS,
    CommandResult,
    Sandbox,
    SandboxError,
    SandboxKind,
    SandboxLimits,
    SandboxSpec,
)
from workers.sandbox.cleanup import remove_labelled
from workers.sandbox.repo_copy import check_repo


def check_ready(kind: SandboxKind | str, image: str, *, trust: str | None = None) -> None:
    """SandboxError (one line) unless a sandbox of ``kind`` can start here: for ``docker`` the
    daemon answers and ``image`` exists (checked before a sweep runs: a missing image is refused
    in preflight, not found by an episode); for ``local`` bubblewrap works, unless ``trust`` is
    ``none`` (:func:`workers.sandbox.local_sandbox.refusal`)."""
    if kind not in SANDBOX_KINDS:
        raise SandboxError(f"unknown sandbox kind {kind!r} (known: {', '.join(SANDBOX_KINDS)})")
    if kind == "local":
        from workers.sandbox.local_sandbox import refusal

        refused = refusal(trust)
        if refused is not None:
            raise SandboxError(refused)
    if kind == "docker":
        from workers.sandbox.docker_sandbox import check_image  # the Docker SDK only where docker is asked for

        check_image(image)


def open_sandbox(kind: SandboxKind | str, spec: SandboxSpec, *, trust: str | None = None) -> Sandbox:
    """Start a sandbox of ``kind`` for ``spec``; SandboxError (one line) when it cannot.
    ``trust``: the sweep's ``sandbox_trust`` (``none`` lets a local sandbox run unconfined
    where bubblewrap does not work; None: ``isolated``)."""
    if kind not in SANDBOX_KINDS:
        raise SandboxError(f"unknown sandbox kind {kind!r} (known: {', '.join(SANDBOX_KINDS)})")
    if spec.repo_path is None and kind != "docker":
        raise SandboxError("this repository is inside a Docker image (repo_path None): only a docker sandbox can open it")
    if spec.repo_path is not None:
        check_repo(spec.repo_path, spec.base_commit)
    if kind == "docker":
        from workers.sandbox.docker_sandbox import DockerSandbox

        return DockerSandbox(spec)
    from workers.sandbox.local_sandbox import LocalSandbox

    return LocalSandbox(spec, trust=trust)


__all__ = [
    "LABEL_EPISODE",
    "LABEL_RUN",
    "LABEL_WORKER",
    "SANDBOX_KINDS",
    "CommandResult",
    "Sandbox",
    "SandboxError",
    "SandboxKind",
    "SandboxLimits",
    "SandboxSpec",
    "check_ready",
    "open_sandbox",
    "remove_labelled",
]
