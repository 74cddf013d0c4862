-- Context bound summary per model and arm (successful calls of latest attempts): prompt tokens per
-- call (mean, median, 95th percentile, max), the largest window in messages, and the least-squares
-- slope of prompt tokens over call_index (tokens added per call; near 0 when the context is bounded).
SELECT model_label, arm,
  count(*) AS calls,
  avg(prompt_tokens) AS mean_prompt_tokens,
  quantile_cont(prompt_tokens, 0.5) AS median_prompt_tokens,
  quantile_cont(prompt_tokens, 0.95) AS p95_prompt_tokens,
  max(prompt_tokens) AS max_prompt_tokens,
  max(window_len) AS max_window_messages,
  regr_slope(prompt_tokens, call_index) AS tokens_per_call_slope
FROM calls
WHERE status = 'ok' AND latest_attempt
GROUP BY model_label, arm
ORDER BY model_label, arm;
