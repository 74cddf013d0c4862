-- Main table: pass@1 success rate by model, method arm and environment split (benchmark/split),
-- over the units that finished on their own merits (the outcomes view: capped, gave-up and
-- not-started units are in the coverage table). ALFWorld is one split (alfworld/valid_unseen,
-- its 134 unseen games); its task types are the rows of success_by_task. 95% Wilson score intervals
-- (widened for several seeds per instance: cluster_wilson_low/high in macros.sql).
SELECT model_label, arm, env_split, method, ablation,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  cluster_wilson_low(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_low,
  cluster_wilson_high(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_high,
  count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances,
  instance_deff(list(episode_obs(benchmark, split, task, instance_id, success))) AS deff
FROM outcomes
GROUP BY model_label, arm, env_split, method, ablation
ORDER BY env_split, model_label, arm;
