-- The coding section's two graders side by side: per model, arm and benchmark, the judged coding
-- episodes (evaluations rows of the units counted: the terminal view), how many the official
-- SWE-bench harness graded (official_resolved not null), how many our evaluator and the harness
-- resolved, and the disagreements (ours_resolved <> official_resolved) with their instances.
SELECT t.model_label, t.arm, t.benchmark,
  count(*) AS judged,
  count(e.official_resolved) AS official_graded,
  count(*) FILTER (WHERE e.ours_resolved) AS ours_resolved,
  count(*) FILTER (WHERE e.official_resolved) AS official_resolved,
  count(*) FILTER (WHERE e.ours_resolved <> e.official_resolved) AS disagreements,
  count(*) FILTER (WHERE e.ours_resolved AND NOT e.official_resolved) AS ours_only,
  count(*) FILTER (WHERE e.official_resolved AND NOT e.ours_resolved) AS official_only,
  coalesce(list(t.instance_id ORDER BY t.instance_id) FILTER (WHERE e.ours_resolved <> e.official_resolved), []) AS disagreeing
FROM terminal t
JOIN evaluations e ON e.run_id = t.run_id AND e.episode_id = t.episode_id
WHERE t.benchmark IN ('swe', 'swe-verified')
GROUP BY ALL
ORDER BY t.benchmark, t.model_label, t.arm;
