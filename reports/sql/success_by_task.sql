-- Per-task tables: success rate by task within each environment split, model and arm
-- (latest attempt per unit, 95% Wilson intervals).
SELECT env_split, task, model_label, arm,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  wilson_low(count(*) FILTER (WHERE success), count(*)) AS ci_low,
  wilson_high(count(*) FILTER (WHERE success), count(*)) AS ci_high
FROM terminal
GROUP BY env_split, task, model_label, arm
ORDER BY env_split, task, model_label, arm;
