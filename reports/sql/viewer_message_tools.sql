-- Viewer: the tool fields of the named episodes' messages, where a message has one: an assistant
-- message's calls (JSON) and the call a tool message answers (schema version 5; null before).
SELECT run_id, episode_id, seq, tool_call_id, tool_calls
FROM messages
WHERE list_contains($ids, episode_id) AND (tool_call_id IS NOT NULL OR tool_calls IS NOT NULL)
ORDER BY run_id, episode_id, seq;
