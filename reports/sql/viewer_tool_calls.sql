-- Viewer: the tool calls of the named episodes, in the order they were made (none for a run
-- written before schema version 5, which has no tool_calls rows).
SELECT run_id, episode_id, "index", step_index, call_id, message_seq, node_id, name, arguments, valid,
  error, exit_code, duration_s, output_bytes, timed_out
FROM tool_calls
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id, "index";
