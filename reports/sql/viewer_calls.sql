-- Viewer: the LLM calls of the named episodes with the window (message seqs) each one saw.
SELECT run_id, episode_id, call_index, purpose, status, node_id, response_seq, window_seqs,
  model_label, prompt_tokens, cached_prompt_tokens, completion_tokens, cost_usd, latency_s,
  retries, error_kind, error_message, served_from
FROM calls
WHERE list_contains($ids, episode_id)
ORDER BY run_id, episode_id, call_index;
