-- The coding section's failure modes: every coding unit's row (benchmarks swe and swe-verified; the
-- terminal view, so capped and gave-up units count too) by how it ended - its evaluation's reason
-- (evaluations.reason: resolved, no_patch, patch_failed, tests_failed, timeout) when it was judged,
-- else 'no evaluation: <end_reason>' (a model error, JSON failures, the budget: the episode ended
-- before it submitted) - per model, arm and benchmark, with up to three example episodes.
WITH judged AS (
  SELECT t.model_label, t.arm, t.benchmark, t.episode_id, t.cost_usd,
    coalesce(e.reason, 'no evaluation: ' || t.end_reason) AS outcome
  FROM terminal t
  LEFT JOIN evaluations e ON e.run_id = t.run_id AND e.episode_id = t.episode_id
  WHERE t.benchmark IN ('swe', 'swe-verified')
)
SELECT model_label, arm, benchmark, outcome,
  count(*) AS episodes,
  sum(cost_usd) AS cost_usd,
  list(episode_id ORDER BY episode_id)[1:3] AS examples
FROM judged
GROUP BY ALL
ORDER BY benchmark, model_label, arm, outcome;
