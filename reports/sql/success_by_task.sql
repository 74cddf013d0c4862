-- Per-task tables: success rate by task within each environment split, model and arm, over the
-- finished units (outcomes); ALFWorld's tasks are its task types (put, clean, heat, ...)
-- (latest attempt per unit, 95% Wilson intervals, widened for several seeds per instance).
SELECT env_split, task, model_label, arm,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  cluster_wilson_low(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_low,
  cluster_wilson_high(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_high,
  count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances,
  instance_deff(list(episode_obs(benchmark, split, task, instance_id, success))) AS deff
FROM outcomes
GROUP BY env_split, task, model_label, arm
ORDER BY env_split, task, model_label, arm;
