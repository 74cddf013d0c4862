-- The coding section's distributions (the paper's "tool call and cost distributions" on SWE-bench
-- Verified, which it finds right-skewed): per model, arm and benchmark, over the finished coding
-- episodes (as coding_episodes.sql), tool calls and cost per episode as mean, median, 90th
-- percentile and maximum, and the resolved count.
WITH e AS (
  SELECT o.model_label, o.arm, o.benchmark, o.success, o.cost_usd, coalesce(t.tool_calls, 0) AS tool_calls
  FROM outcomes o
  LEFT JOIN tool_stats t ON t.run_id = o.run_id AND t.episode_id = o.episode_id
  WHERE o.benchmark IN ('swe', 'swe-verified')
)
SELECT model_label, arm, benchmark,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS resolved,
  avg(tool_calls) AS calls_mean,
  quantile_cont(tool_calls, 0.5) AS calls_median,
  quantile_cont(tool_calls, 0.9) AS calls_p90,
  max(tool_calls) AS calls_max,
  avg(cost_usd) AS cost_mean,
  quantile_cont(cost_usd, 0.5) AS cost_median,
  quantile_cont(cost_usd, 0.9) AS cost_p90,
  max(cost_usd) AS cost_max
FROM e
GROUP BY ALL
ORDER BY benchmark, model_label, arm;
