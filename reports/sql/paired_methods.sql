-- Paired comparisons: every two arms of the same model and environment split, on the units both
-- finished (same task, instance and seed; the outcomes view). a_only / b_only are the discordant pairs;
-- p_value is the exact two-sided McNemar test. cost_diffs (arm_a minus arm_b, per pair, in pair
-- order) feed the paired permutation test of the mean cost difference.
WITH per_unit AS (
  SELECT model_label, env_split, arm, task, instance_id, seed,
    arg_max(success, ended_at) AS success,
    arg_max(cost_usd, ended_at) AS cost_usd
  FROM outcomes
  GROUP BY ALL
), counted AS (
  SELECT a.model_label, a.env_split, a.arm AS arm_a, b.arm AS arm_b,
    count(*) AS pairs,
    count(*) FILTER (WHERE a.success) AS a_successes,
    count(*) FILTER (WHERE b.success) AS b_successes,
    count(*) FILTER (WHERE a.success AND NOT b.success) AS a_only,
    count(*) FILTER (WHERE b.success AND NOT a.success) AS b_only,
    avg(a.cost_usd - b.cost_usd) AS mean_cost_diff,
    list(a.cost_usd - b.cost_usd ORDER BY a.task, a.instance_id, a.seed) AS cost_diffs
  FROM per_unit a
  JOIN per_unit b
    ON a.model_label = b.model_label AND a.env_split = b.env_split AND a.arm < b.arm
   AND a.task = b.task AND a.instance_id = b.instance_id AND a.seed = b.seed
  GROUP BY ALL
)
SELECT model_label, env_split, arm_a, arm_b, pairs, a_successes, b_successes,
  (a_successes - b_successes) / pairs AS rate_diff,
  a_only, b_only,
  mcnemar_p(a_only, b_only) AS p_value,
  mean_cost_diff, cost_diffs
FROM counted
ORDER BY env_split, model_label, arm_a, arm_b;
