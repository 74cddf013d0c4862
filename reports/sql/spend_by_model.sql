-- Spend by model over every LLM call of every attempt (what was paid, retries and lost attempts
-- included). A failed call has no model of its own and is counted under its episode's model.
SELECT model_label,
  count(*) AS calls,
  count(*) FILTER (WHERE status = 'error') AS failed_calls,
  sum(retries) AS retries,
  sum(prompt_tokens) AS prompt_tokens,
  sum(cached_prompt_tokens) AS cached_prompt_tokens,
  sum(completion_tokens) AS completion_tokens,
  sum(cached_prompt_tokens) / nullif(sum(prompt_tokens), 0) AS cached_share,
  sum(cost_usd) AS cost_usd,
  sum(cost_usd) / nullif(sum(sum(cost_usd)) OVER (), 0) AS spend_share
FROM calls
GROUP BY model_label
ORDER BY cost_usd DESC, model_label;
