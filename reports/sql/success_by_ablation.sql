-- Ablation table: success rate by ablation (episodes.ablation; 'original' for the method itself),
-- per model, method (its name), profile, environment split and window size, over the finished
-- units (outcomes), with a clustered McNemar test against the 'original' arm of the same
-- model/method/profile/split/window on the units both finished (paired on task, instance, seed;
-- the arms swapped per instance, all its seeds together: clustered_mcnemar_p, which is the exact
-- McNemar test when every instance ran one seed). original_only / variant_only are the discordant
-- pairs; paired_instances the instances they ran; p_value is NULL without paired units. instances and deff (the design effect of several
-- seeds per instance, instance_deff) say how the 95% interval was widened.
WITH per_unit AS (
  SELECT model_label, method, coalesce(profile, '') AS pr, env_split, coalesce(window_size, -1) AS w, ablation,
    benchmark, split, task, instance_id, sampling_seed,
    arg_max(success, ended_at) AS success
  FROM outcomes
  GROUP BY ALL
), rates AS (
  SELECT model_label, method, profile, env_split, window_size, ablation,
    count(*) AS episodes,
    count(*) FILTER (WHERE success) AS successes,
    list(episode_obs(benchmark, split, task, instance_id, success)) AS obs,
    count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances
  FROM outcomes
  GROUP BY ALL
), pairs AS (
  SELECT v.model_label, v.method, v.pr, v.env_split, v.w, v.ablation,
    count(*) AS pairs,
    count(*) FILTER (WHERE o.success AND NOT v.success) AS original_only,
    count(*) FILTER (WHERE v.success AND NOT o.success) AS variant_only,
    count(DISTINCT instance_key(v.benchmark, v.split, v.task, v.instance_id)) AS paired_instances,
    clustered_mcnemar_p(list(pair_obs(v.benchmark, v.split, v.task, v.instance_id, o.success, v.success))) AS p_value
  FROM per_unit v
  JOIN per_unit o
    ON o.ablation = 'original' AND v.ablation <> 'original'
   AND o.model_label = v.model_label AND o.method = v.method AND o.pr = v.pr AND o.env_split = v.env_split AND o.w = v.w
   AND o.benchmark = v.benchmark AND o.split = v.split
   AND o.task = v.task AND o.instance_id = v.instance_id AND o.sampling_seed = v.sampling_seed
  GROUP BY v.model_label, v.method, v.pr, v.env_split, v.w, v.ablation
)
SELECT r.model_label, r.method, r.profile, r.env_split, r.window_size, r.ablation,
  r.episodes, r.successes,
  r.successes / r.episodes AS success_rate,
  cluster_wilson_low(r.obs) AS ci_low,
  cluster_wilson_high(r.obs) AS ci_high,
  r.instances, instance_deff(r.obs) AS deff,
  p.pairs, p.paired_instances, p.original_only, p.variant_only, p.p_value
FROM rates r
LEFT JOIN pairs p
  ON p.model_label = r.model_label AND p.method = r.method AND p.pr = coalesce(r.profile, '') AND p.env_split = r.env_split
 AND p.w = coalesce(r.window_size, -1) AND p.ablation = r.ablation
ORDER BY r.model_label, r.method, r.profile NULLS FIRST, r.env_split, r.window_size, r.ablation = 'original' DESC, r.ablation;
