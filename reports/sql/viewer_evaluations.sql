-- Viewer: how the named episodes' submissions were judged (SWE-bench: the evaluations table, one row per
-- judged episode; none for any other benchmark): verdict, graders, per-test statuses, diff and log.
SELECT run_id, episode_id, resolved, reason, graded_by, grading, ours_resolved, official_resolved,
  official_status, official_parser, tests, fail_to_pass_passed, fail_to_pass_total, pass_to_pass_passed,
  pass_to_pass_total, patch, patch_bytes, log, log_bytes, duration_s
FROM evaluations
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id;
