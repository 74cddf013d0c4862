-- The coding section's episodes (the paper's "tool call and cost distributions" figure): one row per
-- finished coding episode (benchmarks swe and swe-verified; the outcomes view: capped, gave-up and
-- not-started units are in the coverage table), with its tool calls (tool_stats: calls recorded,
-- valid or not; 0 when the episode made none), its cost and whether it resolved the issue.
SELECT o.model_label, o.arm, o.method, o.benchmark, o.instance_id, o.episode_id,
  o.success AS resolved,
  coalesce(t.tool_calls, 0) AS tool_calls,
  o.cost_usd,
  o.end_reason
FROM outcomes o
LEFT JOIN tool_stats t ON t.run_id = o.run_id AND t.episode_id = o.episode_id
WHERE o.benchmark IN ('swe', 'swe-verified')
ORDER BY o.benchmark, o.model_label, o.arm, o.instance_id, o.episode_id;
