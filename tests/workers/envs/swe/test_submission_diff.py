"""One diff, one verdict (issue 36 item 3): the byte-code a run leaves is not handed in, and the
diff that is gets the same verdict in the local sandbox and in Docker.

A user's task whose repository has no ``.gitignore``: the model fixes the code and imports it (a
reproduction run), which writes ``__pycache__/*.pyc``; ``git add -A && git diff --cached`` then
holds a binary block that ``git apply`` refuses. Before the fix the local sandbox (GNU ``patch``
on the host) resolved it and Docker (no ``patch`` in the image) said ``patch_failed``.
"""

from __future__ import annotations

import json
import subprocess
import sys
import uuid
from collections.abc import Iterator
from functools import partial
from pathlib import Path

import pytest

from workers.envs.registry import make_env
from workers.envs.swe.env import SUBMIT_SENTINEL, SweEnvironment
from workers.envs.swe.evaluate import evaluate
from workers.envs.swe.examples import make_fixtures
from workers.envs.swe.instances import load_instances
from workers.envs.swe.submission_diff import SubmissionDiff, is_build_file, without_build_files
from workers.sandbox import LABEL_RUN, SandboxSpec, open_sandbox, remove_labelled

KINDS = [pytest.param("docker", marks=pytest.mark.docker), "local"]
PYC = f"__pycache__/mathutil.cpython-{sys.version_info.major}{sys.version_info.minor}.pyc"
#: the fix of the ``offbyone`` fixture, as ``git diff`` writes it
FIX = (
    "diff --git a/mathutil.py b/mathutil.py\n"
    "index 5c3a2b5..9b0b2a8 100644\n"
    "--- a/mathutil.py\n"
    "+++ b/mathutil.py\n"
    "@@ -1,6 +1,6 @@\n"
    " def count_range(a, b):\n"
    '     """The integers from a to b, both included."""\n'
    "-    return list(range(a, b))\n"
    "+    return list(range(a, b + 1))\n"
    " \n"
    " \n"
    " def total(xs):\n"
)


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(
        ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=repo, check=True, capture_output=True, text=True
    ).stdout


@pytest.fixture
def no_gitignore_task(tmp_path: Path) -> Path:
    """The ``offbyone`` fixture as a user's task without a ``.gitignore``: its instances file."""
    fx = make_fixtures(tmp_path / "tasks", ("offbyone",))
    repo = fx.tasks_file.parent / "repos" / "offbyone"
    _git(repo, "rm", "-q", ".gitignore")
    _git(repo, "commit", "-q", "--amend", "-m", "base without .gitignore")
    rec = json.loads(fx.tasks_file.read_text())
    rec["base_commit"] = _git(repo, "rev-parse", "HEAD").strip()
    fx.tasks_file.write_text(json.dumps(rec) + "\n")
    return fx.tasks_file


def _fix_index_line(diff: str) -> str:
    """:data:`FIX` with the ``index`` line of ``diff``'s mathutil.py block (blob ids depend on nothing we
    choose, but are read rather than assumed)."""
    index = next(line for line in diff.splitlines() if line.startswith("index ") and ".." in line and "100644" in line)
    return FIX.replace("index 5c3a2b5..9b0b2a8 100644", index)


def _raw_diff(repo: Path) -> str:
    """The fix plus a run's byte-code, taken as the release takes a submission (``git add -A && git
    diff --cached``), the tree put back afterwards."""
    text = (repo / "mathutil.py").read_text().replace("range(a, b))", "range(a, b + 1))")
    (repo / "mathutil.py").write_text(text)
    subprocess.run([sys.executable, "-m", "py_compile", "mathutil.py"], cwd=repo, check=True)
    _git(repo, "add", "-A")
    raw = _git(repo, "diff", "--cached", "HEAD")
    _git(repo, "reset", "-q", "--hard", "HEAD")
    _git(repo, "clean", "-fdxq")
    return raw


# -- the filter ------------------------------------------------------------------------------------
def test_a_runs_bytecode_is_left_out_and_git_apply_then_applies(no_gitignore_task: Path, tmp_path: Path) -> None:
    repo = no_gitignore_task.parent / "repos" / "offbyone"
    raw = _raw_diff(repo)
    fix = _fix_index_line(raw)
    pyc_block = f"diff --git a/{PYC} b/{PYC}\nnew file mode 100644\n"
    assert raw.startswith(pyc_block)  # git sorts __pycache__ before mathutil.py
    assert f"Binary files /dev/null and b/{PYC} differ\n" in raw
    assert raw.endswith(fix)
    assert without_build_files(raw) == SubmissionDiff(fix, (PYC,))
    # git apply refuses the raw diff whole and applies what is handed in
    (tmp_path / "raw.patch").write_text(raw)
    (tmp_path / "kept.patch").write_text(fix)
    refused = subprocess.run(["git", "apply", "--check", str(tmp_path / "raw.patch")], cwd=repo, capture_output=True, text=True)
    assert refused.returncode == 1
    assert f"error: cannot apply binary patch to '{PYC}' without full index line" in refused.stderr
    _git(repo, "apply", "--check", str(tmp_path / "kept.patch"))


def test_only_header_lines_decide_and_every_other_block_is_kept_byte_for_byte() -> None:
    text_block = (
        "diff --git a/notes.md b/notes.md\nindex 1111111..2222222 100644\n--- a/notes.md\n+++ b/notes.md\n"
        "@@ -1 +1,2 @@\n line\n+Binary files a/x and b/x differ\n"
    )
    new_module = (
        "diff --git a/pkg/new.py b/pkg/new.py\nnew file mode 100644\nindex 0000000..3333333\n--- /dev/null\n"
        "+++ b/pkg/new.py\n@@ -0,0 +1 @@\n+X = 1\r\n"
    )
    tracked_binary = (
        "diff --git a/logo.png b/logo.png\nindex 4444444..5555555 100644\nBinary files a/logo.png and b/logo.png differ\n"
    )
    text_in_cache = (
        "diff --git a/pkg/__pycache__/notes.txt b/pkg/__pycache__/notes.txt\nnew file mode 100644\n"
        "index 0000000..6666666\n--- /dev/null\n+++ b/pkg/__pycache__/notes.txt\n@@ -0,0 +1 @@\n+cache\n"
    )
    changed_tracked_cache = (
        "diff --git a/vendor/__pycache__/keep.txt b/vendor/__pycache__/keep.txt\nindex 7777777..8888888 100644\n"
        "--- a/vendor/__pycache__/keep.txt\n+++ b/vendor/__pycache__/keep.txt\n@@ -1 +1 @@\n-a\n+b\n"
    )
    diff = text_block + tracked_binary + new_module + text_in_cache + changed_tracked_cache
    assert without_build_files(diff) == SubmissionDiff(
        text_block + new_module + changed_tracked_cache, ("logo.png", "pkg/__pycache__/notes.txt")
    )
    assert without_build_files("") == SubmissionDiff("", ())
    assert without_build_files(text_block) == SubmissionDiff(text_block, ())


@pytest.mark.parametrize(
    ("path", "build"),
    [
        ("__pycache__/m.cpython-311.pyc", True),
        ("a/b/__pycache__/x.txt", True),
        ("old.pyc", True),
        ("pkg/mod.pyo", True),
        ("pkg/mod.py", False),
        ("__pycache__", False),  # a file of that name, not a folder
        ("docs/pyc.md", False),
    ],
)
def test_is_build_file(path: str, build: bool) -> None:
    assert is_build_file(path) is build


# -- one diff, one verdict in both sandboxes -------------------------------------------------------
@pytest.fixture
def labels() -> Iterator[dict[str, str]]:
    lab = {LABEL_RUN: f"test-{uuid.uuid4().hex[:12]}"}
    yield lab
    remove_labelled(lab)


@pytest.mark.parametrize("kind", KINDS)
def test_the_raw_diff_with_bytecode_is_resolved_in_both_sandboxes(
    kind: str, no_gitignore_task: Path, labels: dict[str, str], request: pytest.FixtureRequest
) -> None:
    """The evaluation's half: the diff as main took it (binary block included) applies in both
    sandboxes (``patch``, the harness's last fallback, is in the image) and resolves."""
    request.getfixturevalue("docker_ready" if kind == "docker" else "bwrap_ready")
    (instance,) = load_instances(no_gitignore_task)
    raw = _raw_diff(no_gitignore_task.parent / "repos" / "offbyone")
    spec = SandboxSpec(instance.repo_path, instance.base_commit, labels=labels)
    ev = evaluate(instance, raw, partial(open_sandbox, kind, spec), grading="ours")
    assert (ev.resolved, ev.reason) == (True, "resolved"), ev.log
    assert ev.tests == {
        "tests/test_mathutil.py::test_count_range_inclusive": "PASSED",
        "tests/test_mathutil.py::test_total": "PASSED",
    }


@pytest.mark.parametrize("kind", KINDS)
def test_a_fix_and_a_run_that_wrote_bytecode_get_one_verdict_in_both_sandboxes(
    kind: str, no_gitignore_task: Path, labels: dict[str, str], request: pytest.FixtureRequest
) -> None:
    """The episode's half: the model fixes the code, a run writes ``__pycache__/*.pyc``, it submits;
    the diff handed in is the fix alone, and it resolves, in each sandbox alike."""
    request.getfixturevalue("docker_ready" if kind == "docker" else "bwrap_ready")
    env = make_env(
        "swe/fixture__offbyone-1",
        instances_file=str(no_gitignore_task),
        sandbox=kind,
        sandbox_labels=labels,
        grading="ours",
    )
    assert isinstance(env, SweEnvironment)
    try:
        env.reset()
        edit = env.step("sed -i 's/range(a, b))/range(a, b + 1))/' mathutil.py")
        assert (edit.done, edit.info["exit_code"]) == (False, 0), edit.observation
        run = env.step(
            "env -u PYTHONDONTWRITEBYTECODE python -c 'import mathutil; print(mathutil.count_range(1, 3))' && ls __pycache__"
        )
        assert run.observation.splitlines()[:2] == ["[1, 2, 3]", PYC.split("/")[1]], run.observation
        done = env.step(f"echo {SUBMIT_SENTINEL}")
    finally:
        env.close()
    assert (done.done, done.success) == (True, True), done.info
    assert (done.info["resolved"], done.info["eval_reason"]) == (True, "resolved")
    assert done.info["patch"] == _fix_index_line(done.info["patch"])
