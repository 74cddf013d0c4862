-- The coding section's resolve rate by number of tool calls (the paper's SWE-bench figure "task
-- resolve rate by number of tool calls"): finished coding episodes (as coding_episodes.sql) binned by
-- their tool calls - 0-9, 10-24, 25-49, 50-99, 100-199, 200 and more (the paper's episodes range
-- from 5 to 257 steps and it notes the rate above 100 calls) - per model, arm and benchmark: episodes,
-- resolved, the resolved share with its 95% Wilson interval (episodes taken as independent).
WITH e AS (
  SELECT o.model_label, o.arm, o.benchmark, o.success, coalesce(t.tool_calls, 0) AS tool_calls
  FROM outcomes o
  LEFT JOIN tool_stats t ON t.run_id = o.run_id AND t.episode_id = o.episode_id
  WHERE o.benchmark IN ('swe', 'swe-verified')
), binned AS (
  SELECT *,
    CASE WHEN tool_calls < 10 THEN 0 WHEN tool_calls < 25 THEN 10 WHEN tool_calls < 50 THEN 25
         WHEN tool_calls < 100 THEN 50 WHEN tool_calls < 200 THEN 100 ELSE 200 END AS bin_low
  FROM e
)
SELECT model_label, arm, benchmark, bin_low,
  CASE bin_low WHEN 0 THEN 9 WHEN 10 THEN 24 WHEN 25 THEN 49 WHEN 50 THEN 99 WHEN 100 THEN 199 END AS bin_high,
  CASE bin_low WHEN 200 THEN '200+' ELSE bin_low || '-' || CASE bin_low WHEN 0 THEN 9 WHEN 10 THEN 24 WHEN 25 THEN 49
    WHEN 50 THEN 99 ELSE 199 END END AS bin,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS resolved,
  count(*) FILTER (WHERE success) / count(*) AS resolve_rate,
  wilson_low(count(*) FILTER (WHERE success), count(*)) AS ci_low,
  wilson_high(count(*) FILTER (WHERE success), count(*)) AS ci_high
FROM binned
GROUP BY ALL
ORDER BY benchmark, model_label, arm, bin_low;
