"""The code revision a run records: a run folder inside the checkout is not a code change."""

from __future__ import annotations

import subprocess

import pipeline.provenance as provenance


def test_untracked_outputs_do_not_mark_the_revision_dirty(tmp_path, monkeypatch):
    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=tmp_path, check=True, capture_output=True, text=True).stdout.strip()

    git("init", "-q")
    (tmp_path / "code.py").write_text("x = 1\n")
    git("add", "code.py")
    git("-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    head = git("rev-parse", "HEAD")
    monkeypatch.setattr(provenance, "PROJECT_ROOT", tmp_path)
    (tmp_path / "results" / "run1").mkdir(parents=True)
    (tmp_path / "results" / "run1" / "run.json").write_text("{}")
    assert provenance.git_revision() == head
    (tmp_path / "code.py").write_text("x = 2\n")
    assert provenance.git_revision() == head + "+dirty"
