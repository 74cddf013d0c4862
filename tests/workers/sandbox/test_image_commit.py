"""Which commit an image's repository may be at (``docker_sandbox.image_commit``), on local repositories.

The SWE-bench harness (swebench 4.x ``harness/test_spec/python.py`` ``make_repo_script_list_py``)
builds an instance image by resetting /testbed to the base commit, installing, and committing
``git commit --allow-empty -am SWE-bench`` on top; its images are at that commit, not at the base
commit. These tests lay a repository out that way with git itself and hand ``image_commit`` a
runner of commands in it (what the docker sandbox hands it: its own ``run``).
"""

from __future__ import annotations

import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

from workers.sandbox.base import CommandResult, SandboxError
from workers.sandbox.docker_sandbox import HARNESS_COMMIT_SUBJECT, image_commit

WHERE = "/testbed in the image sweb.eval.x86_64.demo__demo-1:latest"


def git(repo: Path, *args: str) -> str:
    env = {"GIT_AUTHOR_DATE": "2024-01-01T00:00:00Z", "GIT_COMMITTER_DATE": "2024-01-01T00:00:00Z", "HOME": str(repo.parent)}
    done = subprocess.run(["git", "-C", str(repo), *args], capture_output=True, text=True, check=True, env=env)
    return done.stdout.strip()


def runner(repo: Path) -> Callable[[str], CommandResult]:
    """``bash -c`` in ``repo``, output and exit code as the sandbox reports them."""

    def run(command: str) -> CommandResult:
        done = subprocess.run(["bash", "-c", command], cwd=repo, capture_output=True, text=True)
        out = done.stdout + done.stderr
        return CommandResult(done.returncode, out, len(out), 0.0)

    return run


@pytest.fixture
def repo(tmp_path: Path) -> tuple[Path, str]:
    """A repository at its base commit (two commits of history), and that commit's hash."""
    r = tmp_path / "testbed"
    r.mkdir()
    git(r, "init", "-q")
    git(r, "config", "user.name", "upstream")
    git(r, "config", "user.email", "upstream@example.invalid")
    (r / "setup.cfg").write_text("[tool]\nrunner = pytest\n")
    (r / "mod.py").write_text("x = 1\n")
    git(r, "add", "-A")
    git(r, "commit", "-q", "-m", "first")
    (r / "mod.py").write_text("x = 2\n")
    git(r, "commit", "-q", "-am", "the base commit")
    return r, git(r, "rev-parse", "HEAD")


def harness_commit(r: Path, *, edit_tracked: bool = False, subject: str = HARNESS_COMMIT_SUBJECT) -> str:
    """What the harness's setup script ends with (its user, then ``commit --allow-empty -am``); with
    ``edit_tracked`` the install step first changed a tracked file (as its sed on a tox.ini does)."""
    if edit_tracked:
        (r / "setup.cfg").write_text("[tool]\nrunner = pytest -rA\n")
    git(r, "config", "user.email", "setup@swebench.config")
    git(r, "config", "user.name", "SWE-bench")
    git(r, "commit", "-q", "--allow-empty", "-am", subject)
    return git(r, "rev-parse", "HEAD")


def test_an_image_at_the_base_commit_is_taken_at_it(repo) -> None:
    r, base = repo
    assert image_commit(runner(r), base, WHERE) == base
    assert image_commit(runner(r), base[:12], WHERE) == base  # an abbreviated base commit names the same


def test_the_harness_layout_is_taken_at_its_own_commit(repo) -> None:
    """Refused before the fix: '/testbed ... is at <SWE-bench commit>, not at base_commit <base>'."""
    r, base = repo
    head = harness_commit(r)
    assert head != base
    assert image_commit(runner(r), base, WHERE) == head


def test_the_harness_commit_holds_what_the_install_changed_and_is_still_taken(repo) -> None:
    r, base = repo
    head = harness_commit(r, edit_tracked=True)
    assert git(r, "diff", "--name-only", base, head) == "setup.cfg"
    assert image_commit(runner(r), base, WHERE) == head


@pytest.mark.parametrize(
    "layout",
    ["another subject", "two commits on top", "a commit on another parent", "base commit unknown"],
)
def test_any_other_layout_is_refused_in_one_line(repo, layout: str) -> None:
    r, base = repo
    wanted = base
    if layout == "another subject":  # e.g. an image with the gold patch committed
        head = harness_commit(r, subject="fix the bug")
    elif layout == "two commits on top":
        harness_commit(r, subject="something else")
        head = harness_commit(r)
    elif layout == "a commit on another parent":
        git(r, "checkout", "-q", "HEAD~1")
        head = harness_commit(r)
    else:
        head = harness_commit(r)
        wanted = "0" * 40
    with pytest.raises(SandboxError) as err:
        image_commit(runner(r), wanted, WHERE)
    assert str(err.value) == f"{WHERE} is at {head}, not at base_commit {wanted}"


def test_a_folder_that_is_no_repository_is_refused(tmp_path: Path) -> None:
    with pytest.raises(SandboxError, match=rf"^{WHERE} is not a git repository \(fatal: not a git repository"):
        image_commit(runner(tmp_path), "0" * 40, WHERE)
