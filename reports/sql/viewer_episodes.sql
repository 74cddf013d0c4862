-- Viewer: the named episodes (any attempt) with their labels and failure mode.
SELECT a.run_id, a.episode_id, a.unit_id, a.attempt, a.is_latest, a.model_label, a.arm, a.env_split,
  a.task, a.instance_id, a.sampling_seed, a.end_reason, a.success, a.steps, a.llm_calls, a.prompt_tokens,
  a.cached_prompt_tokens, a.completion_tokens, a.cost_usd, a.wall_s, a.step_cap, a.max_depth,
  a.error, m.mode
FROM attempts a
LEFT JOIN episode_modes m ON m.run_id = a.run_id AND m.episode_id = a.episode_id
WHERE list_contains($ids, a.episode_id)
ORDER BY a.episode_id, a.run_id;
