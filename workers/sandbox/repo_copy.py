"""The repository copy both sandbox kinds start from: a fresh clone of ``repo_path`` at ``base_commit``.

A clone (not a copy of the folder) so that the sandbox holds only committed state at the base
commit, with its own ``.git`` (``git diff`` inside shows exactly the model's edits), and no
remote pointing back at the host's path.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from workers.sandbox.base import SandboxError


def _git(*args: str, cwd: str | Path | None = None) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True)


def check_repo(repo_path: str, base_commit: str) -> str:
    """The full hash of ``base_commit`` in ``repo_path``; SandboxError (one line) when the path is
    not a git repository or the commit is unknown there."""
    p = Path(repo_path)
    if not p.is_dir() or _git("rev-parse", "--git-dir", cwd=p).returncode != 0:
        raise SandboxError(f"repo_path is not a git repository: {repo_path}")
    r = _git("rev-parse", "--verify", "--quiet", f"{base_commit}^{{commit}}", cwd=p)
    if r.returncode != 0 or not r.stdout.strip():
        raise SandboxError(f"base_commit {base_commit!r} is not a commit of {repo_path}")
    return r.stdout.strip()


def clone_at(repo_path: str, base_commit: str, dest: Path) -> str:
    """Clone ``repo_path`` into ``dest`` (which must not exist) and check out ``base_commit``
    (detached). Returns the commit's full hash."""
    commit = check_repo(repo_path, base_commit)
    # --no-local: objects copied, never hard-linked to the host's repository; core.symlinks: a
    # committed symlink stays a symlink (never a file holding its target's path, whatever the
    # host's git config says), and the sandbox resolves it inside its own view (repo_paths)
    r = _git(
        "-c", "core.symlinks=true", "clone", "--quiet", "--no-local", "--no-checkout",
        "--config", "core.symlinks=true", str(Path(repo_path).resolve()), str(dest),
    )  # fmt: skip
    if r.returncode != 0:
        raise SandboxError(f"git clone of {repo_path} failed: {r.stderr.strip().splitlines()[-1:]}")
    if _git("cat-file", "-e", f"{commit}^{{commit}}", cwd=dest).returncode != 0:
        # a commit no branch or tag reaches is not cloned: fetch it by hash
        _git("fetch", "--quiet", "origin", commit, cwd=dest)
    r = _git("checkout", "--quiet", "--detach", commit, cwd=dest)
    if r.returncode != 0:
        raise SandboxError(f"base_commit {base_commit!r} could not be checked out: {r.stderr.strip()}")
    _git("remote", "remove", "origin", cwd=dest)
    return commit
