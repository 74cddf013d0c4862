-- Ablation table: success rate by ablation (episodes.ablation; 'original' for the method itself),
-- per model, method (its name), profile, environment split and window size, over the finished
-- units (outcomes), with a clustered McNemar test against the 'original' arm of the same
-- model/method/profile/split/window on the units both finished (paired on task, instance, seed;
-- the arms swapped per instance, all its seeds together: clustered_mcnemar_p, which is the exact
-- McNemar test when every instance ran one seed). original_only / variant_only are the discordant
-- pairs; paired_instances the instances they ran; p_value is NULL without paired units. instances and deff (the design effect of several
-- seeds per instance, instance_deff) say how the 95% interval was widened.
-- A unit is (run, unit id): a variant and the original that ran one key in several runs pair run by
-- run; the rest pair latest with latest, as in paired_methods.sql.
WITH per_unit AS (
  SELECT run_id, model_label, method, coalesce(profile, '') AS pr, env_split, coalesce(window_size, -1) AS w, ablation,
    benchmark, split, task, instance_id, sampling_seed,
    arg_max(success, ended_at) AS success,
    max(ended_at) AS ended_at
  FROM outcomes
  GROUP BY ALL
), sides AS (
  -- each unit once per ablation it is compared with (a variant with the original, the original
  -- with each variant), marked when that ablation ran the same key in the same run
  SELECT u.*, o.ablation AS other, s.run_id IS NOT NULL AS shared
  FROM per_unit u
  JOIN (SELECT DISTINCT model_label, method, pr, env_split, w, benchmark, split, task, instance_id, sampling_seed, ablation FROM per_unit) o
    ON o.model_label = u.model_label AND o.method = u.method AND o.pr = u.pr AND o.env_split = u.env_split AND o.w = u.w
   AND o.benchmark = u.benchmark AND o.split = u.split AND o.task = u.task AND o.instance_id = u.instance_id
   AND o.sampling_seed = u.sampling_seed AND o.ablation <> u.ablation AND 'original' IN (o.ablation, u.ablation)
  LEFT JOIN per_unit s
    ON s.run_id = u.run_id AND s.ablation = o.ablation AND s.model_label = u.model_label AND s.method = u.method
   AND s.pr = u.pr AND s.env_split = u.env_split AND s.w = u.w AND s.benchmark = u.benchmark AND s.split = u.split
   AND s.task = u.task AND s.instance_id = u.instance_id AND s.sampling_seed = u.sampling_seed
), ranked AS (
  SELECT *, row_number() OVER (
    PARTITION BY model_label, method, pr, env_split, w, benchmark, split, task, instance_id, sampling_seed, ablation, other
    ORDER BY shared DESC, CASE WHEN shared THEN run_id END DESC, ended_at DESC, run_id DESC) AS rep
  FROM sides
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
  FROM ranked v
  JOIN ranked o
    ON o.ablation = 'original' AND v.ablation <> 'original'
   AND o.other = v.ablation AND v.other = 'original' AND o.rep = v.rep
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
