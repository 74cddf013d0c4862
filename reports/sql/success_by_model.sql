-- Cross-model table: success rate by model and arm over every task of the run(s)
-- (the paper averages over Robotouille tasks 2, 4 and 6; a sweep of those tasks gives that number).
SELECT model_label, arm, method, ablation,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  count(*) FILTER (WHERE success) / count(*) AS success_rate,
  wilson_low(count(*) FILTER (WHERE success), count(*)) AS ci_low,
  wilson_high(count(*) FILTER (WHERE success), count(*)) AS ci_high
FROM terminal
GROUP BY model_label, arm, method, ablation
ORDER BY model_label, arm;
