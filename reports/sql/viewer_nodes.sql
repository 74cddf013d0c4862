-- Viewer: the context tree of the named episodes, every version (think, subtasks) of every node.
SELECT run_id, episode_id, node_id, parent_id, depth, child_index, task, kind, status, step_index, versions
FROM tree_nodes
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id, node_id;
