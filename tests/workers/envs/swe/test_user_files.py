"""A user's ``benchmark: swe`` instances file, a model's diff and ``recap data images`` selectors
(issue 35 item 12): each bad input one line, exit 2, nothing written; a model's diff out of the
repository refused before it is applied, as the episode's outcome.

The attacks are the chaos lab's (``tests/pipeline/chaos/user_files.py``, scenario ``userfiles``)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.pipeline.chaos.user_files import (
    BIG_PROBLEM,
    PATCHES,
    Materials,
    images_selector,
    materials,
    model_patch,
    swe_big_problem,
    swe_deep_line,
    swe_record,
    swe_run_inside_repo,
)

BAD_ID = "must be letters, digits, '_', '.' and '-' (starting with a letter or digit, no '..'), got"
ESCAPES = {
    "dotdot": "line 1 of the patch names 'a/../outside.py' (a '..' component), outside the repository",
    "absolute": "line 2 of the patch names the absolute path '/tmp/recap-eval-owned.py', outside the repository",
    "git hook": "line 1 of the patch names 'a/.git/hooks/post-checkout' (inside .git), outside the repository",
    "symlink out": "line 6 of the patch creates the symlink 'etc' to '/etc', outside the repository",
    "quoted dotdot": "line 1 of the patch names 'a/../x.py' (a '..' component), outside the repository",
}


@pytest.fixture(scope="module")
def m(tmp_path_factory: pytest.TempPathFactory) -> Materials:
    return materials(tmp_path_factory.mktemp("userfiles"))


def _line(d: Path, what: str) -> list[str]:
    return [f"recap: error: sweep.yaml: environments[0]: swe task 'all': {d / 'tasks.jsonl'}:{what}"]


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"instance_id": "x/../../y"}, f"field 'instance_id' {BAD_ID} 'x/../../y'"),
        ({"instance_id": "a;id"}, f"field 'instance_id' {BAD_ID} 'a;id'"),
        ({"instance_id": "$(id)"}, f"field 'instance_id' {BAD_ID} '$(id)'"),
        ({"instance_id": "a" * 200}, "field 'instance_id' is 200 characters long, more than 128"),
        ({"repo_path": "/"}, "field 'repo_path': / is the root folder, not a task's repository"),
        (
            {"repo_path": "~"},
            f"field 'repo_path': {Path.home().resolve()} is the home folder or above it, not a task's repository",
        ),
        *(({"patch": PATCHES[k]}, f"field 'patch': {v}") for k, v in ESCAPES.items()),
        ({"test_patch": PATCHES["dotdot"]}, f"field 'test_patch': {ESCAPES['dotdot']}"),
    ],
    ids=lambda v: str(v)[:40],
)
def test_a_bad_record_is_one_line_exit_2_before_anything_runs(m: Materials, tmp_path: Path, change: Any, message: str) -> None:
    res = swe_record(m, tmp_path, change)
    assert (res.code, res.err, res.written) == (2, _line(tmp_path, f"1: {message}"), [])


def test_a_problem_statement_past_1_mib_or_a_line_past_16_mib(m: Materials, tmp_path: Path) -> None:
    res = swe_big_problem(m, tmp_path / "big", BIG_PROBLEM)
    assert (res.code, res.written) == (2, [])
    assert res.err == _line(
        tmp_path / "big", "1: field 'problem_statement' is 2000000 bytes, more than the 1048576 a problem statement may hold"
    )
    res = swe_big_problem(m, tmp_path / "huge", 17 << 20)
    assert (res.code, res.err) == (2, _line(tmp_path / "huge", "1: longer than 16777216 bytes (one record a line)"))


def test_deep_nesting_is_one_line_not_a_recursion_error(m: Materials, tmp_path: Path) -> None:
    res = swe_deep_line(m, tmp_path)
    assert (res.code, res.err, res.written) == (2, _line(tmp_path, "2: nested deeper than 64 levels of arrays/objects"), [])


def test_a_repository_holding_the_run_folder_is_refused_at_preflight(m: Materials, tmp_path: Path) -> None:
    res = swe_run_inside_repo(m, tmp_path)
    repo = m.task()["repo_path"]
    assert (res.code, res.written) == (2, [])
    assert res.err == [
        "recap: error: sweep.yaml: environments[0] (swe): the run folder is inside fixture__offbyone-1's repo_path "
        f"{repo}: put output: outside it"
    ]


@pytest.mark.parametrize("kind", sorted(PATCHES))
def test_a_model_patch_out_of_the_repository_is_refused_unapplied(m: Materials, tmp_path: Path, kind: str) -> None:
    """No clean sandbox is even opened; the verdict is the model's (``patch_refused``)."""
    res = model_patch(m, tmp_path, PATCHES[kind])
    assert res.extra == {"reason": "patch_refused", "success": False, "opened": 0}
    assert res.err == [f"the model's patch was refused before it was applied: {ESCAPES[kind]}"]


def test_the_harness_grading_never_gets_a_refused_patch(m: Materials, monkeypatch: pytest.MonkeyPatch) -> None:
    from workers.envs.swe.env import submitted_text
    from workers.envs.swe_verified import harness_eval
    from workers.envs.swe_verified.benchmark import as_instance
    from workers.envs.swe_verified.env import VerifiedEnvironment

    record = m.verified()
    monkeypatch.setattr(harness_eval.subprocess, "run", lambda *a, **k: pytest.fail("the harness ran"))
    env = VerifiedEnvironment(
        as_instance(record, "unused"),
        lambda spec: pytest.fail("a sandbox was opened"),
        record=record,
        grading="harness",
        image="unused",
    )
    ev = env._evaluate(PATCHES["dotdot"])
    assert (ev.success, ev.verdict_reason, ev.grading, ev.graded_by) == (False, "patch_refused", "harness", "official")
    assert ev.official is not None and ev.official.status is None
    assert ev.log == f"the model's patch was refused before it was applied: {ESCAPES['dotdot']}"
    assert submitted_text(ev).startswith(
        "Your changes were submitted; it was refused unapplied: it writes outside the repository"
    )


def test_patch_headers_only_count_outside_hunks() -> None:
    """A removed line that reads ``--- ../x`` is content; a header after a hunk's counts is read."""
    from workers.envs.swe.patch_paths import patch_refusal

    inside = "diff --git a/x.sql b/x.sql\n--- a/x.sql\n+++ b/x.sql\n@@ -1,2 +1,2 @@\n--- ../x\n+++ /etc/passwd\n"
    assert patch_refusal(inside) is None
    # a form feed inside a line is content (git splits on newlines only), as is a CRLF patch
    feed = "diff --git a/x.py b/x.py\n--- a/x.py\n+++ b/x.py\n@@ -1,3 +1,3 @@\n a\x0c\n--- ../x\n+b\n c\n"
    assert (patch_refusal(feed), patch_refusal(feed.replace("\n", "\r\n"))) == (None, None)
    assert (
        patch_refusal(inside + "rename to ../y\n")
        == "line 7 of the patch names '../y' (a '..' component), outside the repository"
    )
    link_in = "diff --git a/d/l b/d/l\nnew file mode 120000\n--- /dev/null\n+++ b/d/l\n@@ -0,0 +1 @@\n+../x\n"
    assert patch_refusal(link_in) is None
    assert patch_refusal(link_in.replace("+../x", "+../../x")) == (
        "line 6 of the patch creates the symlink 'd/l' to '../../x', outside the repository"
    )


@pytest.mark.parametrize("selector", ["../x", "django__django-1;rm", "", "a/b/c", "x" * 10_000])
def test_images_refuses_a_selector_of_no_selector_form_before_looking_for_data(
    m: Materials, tmp_path: Path, selector: str
) -> None:
    res = images_selector(m, tmp_path, selector)
    shown = repr(selector if len(selector) <= 80 else selector[:77] + "...")
    assert (res.code, res.out, res.written) == (2, [], [])
    assert res.err == [
        f"recap: error: data: {shown} is not a selector: all, a repository (owner/name) or an instance id "
        "(owner__repo-NUMBER, as `recap env list swe-verified` prints them)"
    ]


def test_real_swebench_ids_and_the_fixture_patches_pass(m: Materials) -> None:
    from workers.envs.swe.instances import id_problem
    from workers.envs.swe.patch_paths import patch_refusal

    for iid in ("django__django-11099", "scikit-learn__scikit-learn-14087", "sphinx-doc__sphinx-10435", "psf__requests-2317"):
        assert id_problem(iid) is None
    for i in (0, 1):
        rec = m.task(i)
        assert (patch_refusal(rec["patch"]), patch_refusal(rec["test_patch"])) == (None, None)
