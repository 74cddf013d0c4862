-- The context bound: prompt tokens of each successful call by its position in the episode
-- (call_index), per model and arm, over the latest attempts.
SELECT model_label, arm, call_index,
  count(*) AS calls,
  avg(prompt_tokens) AS mean_prompt_tokens,
  max(prompt_tokens) AS max_prompt_tokens
FROM calls
WHERE status = 'ok' AND latest_attempt
GROUP BY model_label, arm, call_index
ORDER BY model_label, arm, call_index;
