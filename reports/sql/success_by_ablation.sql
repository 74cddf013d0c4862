-- Ablation table: success rate by ablation (settings read from method_config), per model, method,
-- environment split and window size, with an exact McNemar test against the 'original' settings
-- of the same model/method/split/window on the units both ran (paired on task, instance, seed).
-- original_only / variant_only are the discordant pairs; p_value is NULL without paired units.
WITH per_unit AS (
  SELECT model_label, method, env_split, coalesce(window_size, -1) AS w, ablation, task, instance_id, seed,
    arg_max(success, ended_at) AS success
  FROM terminal
  GROUP BY ALL
), rates AS (
  SELECT model_label, method, env_split, window_size, ablation,
    count(*) AS episodes,
    count(*) FILTER (WHERE success) AS successes
  FROM terminal
  GROUP BY ALL
), pairs AS (
  SELECT v.model_label, v.method, v.env_split, v.w, v.ablation,
    count(*) AS pairs,
    count(*) FILTER (WHERE o.success AND NOT v.success) AS original_only,
    count(*) FILTER (WHERE v.success AND NOT o.success) AS variant_only
  FROM per_unit v
  JOIN per_unit o
    ON o.ablation = 'original' AND v.ablation <> 'original'
   AND o.model_label = v.model_label AND o.method = v.method AND o.env_split = v.env_split AND o.w = v.w
   AND o.task = v.task AND o.instance_id = v.instance_id AND o.seed = v.seed
  GROUP BY ALL
)
SELECT r.model_label, r.method, r.env_split, r.window_size, r.ablation,
  r.episodes, r.successes,
  r.successes / r.episodes AS success_rate,
  wilson_low(r.successes, r.episodes) AS ci_low,
  wilson_high(r.successes, r.episodes) AS ci_high,
  p.pairs, p.original_only, p.variant_only,
  CASE WHEN p.pairs IS NOT NULL THEN mcnemar_p(p.original_only, p.variant_only) END AS p_value
FROM rates r
LEFT JOIN pairs p
  ON p.model_label = r.model_label AND p.method = r.method AND p.env_split = r.env_split
 AND p.w = coalesce(r.window_size, -1) AND p.ablation = r.ablation
ORDER BY r.model_label, r.method, r.env_split, r.window_size, r.ablation = 'original' DESC, r.ablation;
