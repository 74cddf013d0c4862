"""Fixtures of the sandbox tests: a tiny git repository, both sandbox kinds, the docker image.

Docker tests carry the ``docker`` marker (``pytest -m docker`` runs them alone). Without a
reachable daemon they FAIL with the reason; RECAP_SKIP_DOCKER=1 is the explicit opt-out (then
they are skipped, saying so). The image is built once per session if missing (idempotent).
"""

from __future__ import annotations

import subprocess
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

from workers.sandbox import LABEL_RUN, Sandbox, SandboxLimits, SandboxSpec, open_sandbox, remove_labelled

KINDS = [pytest.param("docker", marks=pytest.mark.docker), "local"]


@dataclass(frozen=True)
class Repo:
    """A tiny repository: ``a.txt`` holds ``hello``, one commit."""

    path: Path
    commit: str


def git(*args: str, cwd: Path) -> str:
    return subprocess.run(
        ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=cwd, check=True, capture_output=True, text=True
    ).stdout.strip()


@pytest.fixture
def repo(tmp_path: Path) -> Repo:
    p = tmp_path / "repo"
    p.mkdir()
    git("init", "-q", cwd=p)
    (p / "a.txt").write_text("hello\n")
    git("add", ".", cwd=p)
    git("commit", "-qm", "first", cwd=p)
    commit = git("rev-parse", "HEAD", cwd=p)
    (p / "a.txt").write_text("uncommitted\n")  # the sandbox must show the commit, not the work tree
    return Repo(p, commit)


@pytest.fixture
def labels() -> Iterator[dict[str, str]]:
    """Unique labels; whatever carries them is removed after the test."""
    lab = {LABEL_RUN: f"test-{uuid.uuid4().hex[:12]}"}
    yield lab
    remove_labelled(lab)


@pytest.fixture(params=KINDS)
def open_kind(request: pytest.FixtureRequest, repo: Repo, labels: dict[str, str]) -> Iterator[Callable[..., Sandbox]]:
    """``open_kind(**limits)``: a sandbox of the test's kind on ``repo``, closed afterwards."""
    kind = request.param
    if kind == "docker":
        request.getfixturevalue("docker_ready")
    opened: list[Sandbox] = []

    def make(env: dict[str, str] | None = None, **limits: object) -> Sandbox:
        spec = SandboxSpec(str(repo.path), repo.commit, limits=SandboxLimits(**limits), env=env or {}, labels=labels)
        sb = open_sandbox(kind, spec)
        opened.append(sb)
        return sb

    yield make
    for sb in opened:
        sb.close()
