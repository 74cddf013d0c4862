"""The failure taxonomy of coding episodes reads the evaluation's verdict (issue 36 item 7): a judged
submission that did not resolve is ``tests_failed`` / ``patch_failed`` / ``patch_refused`` /
``no_patch`` / ``timeout`` (``autosubmitted:<reason>`` when a limit handed the diff in), never
``agent_done_early``; an episode without an evaluation keeps the end-reason rules."""

from __future__ import annotations

from pathlib import Path

from reports.views import open_runs
from tests.doubles.swe_run import Episode, write_swe_run

#: (instance, end_reason, evaluation) of the extra fixture-benchmark episodes, arm recap
EXTRA: tuple[Episode, ...] = (
    ("recap", "recap", "refused", "agent_done", 3, 0.1, ("patch_refused", False, None)),
    ("recap", "recap", "emptydiff", "agent_done", 2, 0.1, ("no_patch", False, None)),
    ("recap", "recap", "limit", "autosubmitted", 30, 1.0, ("tests_failed", False, None)),
    ("recap", "recap", "limitrefused", "autosubmitted", 30, 1.0, ("patch_refused", False, None)),
    ("recap", "recap", "limitnorow", "autosubmitted", 30, 1.0, None),
    ("recap", "recap", "looped", "agent_done", 4, 0.2, ("tests_failed", False, None)),
    ("recap", "recap", "loopednorow", "agent_done", 4, 0.2, None),
    ("recap", "recap", "declared", "agent_done", 1, 0.1, None),
)
#: four identical (action, observation) steps: a repeated-action loop (cycle 1)
LOOP = [("bash: python repro.py", "Traceback: ValueError")] * 4


def test_every_coding_episode_gets_its_evaluations_reason_as_its_failure_mode(tmp_path: Path) -> None:
    run = write_swe_run(
        tmp_path / "runS",
        extra=[("swe", "custom", ep, 0.0) for ep in EXTRA],
        steps={"swe-recap-looped-1": LOOP, "swe-recap-loopednorow-1": LOOP},
    )
    con = open_runs([run])
    rows = con.execute("SELECT episode_id, end_reason, mode FROM episode_modes ORDER BY episode_id").fetchall()
    assert rows == [
        ("swe-recap-add-1", "success", "success"),
        ("swe-recap-declared-1", "agent_done", "agent_done_early"),  # no evaluation: the agent's word
        ("swe-recap-emptydiff-1", "agent_done", "no_patch"),
        ("swe-recap-greet-1", "agent_done", "tests_failed"),
        ("swe-recap-limit-1", "autosubmitted", "autosubmitted:tests_failed"),
        ("swe-recap-limitnorow-1", "autosubmitted", "autosubmitted"),
        ("swe-recap-limitrefused-1", "autosubmitted", "autosubmitted:patch_refused"),
        ("swe-recap-looped-1", "agent_done", "tests_failed"),  # the verdict before the loop detector
        ("swe-recap-loopednorow-1", "agent_done", "repeated_action_loop"),
        ("swe-recap-refused-1", "agent_done", "patch_refused"),
        ("swe-verified-mini_swe-django__django-1-1", "success", "success"),
        ("swe-verified-mini_swe-django__django-2-1", "agent_done", "patch_failed"),
        ("swe-verified-mini_swe-django__django-3-1", "llm_error", "model_error:unknown"),
        ("swe-verified-mini_swe-django__django-4-1", "agent_done", "tests_failed"),  # ours resolved, the official grade did not
        ("swe-verified-react-django__django-1-1", "agent_done", "timeout"),
        ("swe-verified-react-django__django-2-1", "budget_exhausted", "budget_exhausted"),
        ("swe-verified-react-django__django-3-1", "success", "success"),
        ("swe-verified-react-django__django-4-1", "json_failures", "json_failures"),
        ("swe-verified-recap-django__django-1-1", "success", "success"),
        ("swe-verified-recap-django__django-2-1", "agent_done", "tests_failed"),
        ("swe-verified-recap-django__django-3-1", "success", "success"),
        ("swe-verified-recap-django__django-4-1", "step_cap", "step_cap"),  # only a submission's verdict is read
    ]
    # the failures view (the report's failure-mode table) counts the same modes; the capped unit is not there
    modes = con.execute("SELECT mode, count(*) FROM failures GROUP BY mode ORDER BY mode").fetchall()
    assert modes == [
        ("agent_done_early", 1),
        ("autosubmitted", 1),
        ("autosubmitted:patch_refused", 1),
        ("autosubmitted:tests_failed", 1),
        ("json_failures", 1),
        ("model_error:unknown", 1),
        ("no_patch", 1),
        ("patch_failed", 1),
        ("patch_refused", 1),
        ("repeated_action_loop", 1),
        ("step_cap", 1),
        ("tests_failed", 4),
        ("timeout", 1),
    ]
