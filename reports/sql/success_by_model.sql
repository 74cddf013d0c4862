-- Cross-model table: success rate by model and arm over every task of the run(s), finished units
-- (the paper averages over Robotouille tasks 2, 4 and 6; a sweep of those tasks gives that number).
SELECT model_label, arm, method, ablation,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  cluster_wilson_low(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_low,
  cluster_wilson_high(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_high,
  count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances,
  instance_deff(list(episode_obs(benchmark, split, task, instance_id, success))) AS deff
FROM outcomes
GROUP BY model_label, arm, method, ablation
ORDER BY model_label, arm;
