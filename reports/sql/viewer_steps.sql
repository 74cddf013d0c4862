-- Viewer: the actions and observations of the named episodes.
SELECT run_id, episode_id, "index", env_step, action, valid, observation, done, success, node_id
FROM steps
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id, "index";
