-- Viewer: the messages of the named episodes (each stored once; calls refer to them by seq).
SELECT run_id, episode_id, seq, role, kind, node_id, pinned, content
FROM messages
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id, seq;
