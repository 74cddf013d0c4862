-- Main table: pass@1 success rate by model, method arm and environment split (benchmark/split),
-- over the latest attempt of every unit, with 95% Wilson score intervals.
SELECT model_label, arm, env_split, method, ablation,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  wilson_low(count(*) FILTER (WHERE success), count(*)) AS ci_low,
  wilson_high(count(*) FILTER (WHERE success), count(*)) AS ci_high
FROM terminal
GROUP BY model_label, arm, env_split, method, ablation
ORDER BY env_split, model_label, arm;
