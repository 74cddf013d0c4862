-- Costs per model, arm and environment split, from the rows of the finished units (outcomes):
-- dollars and tokens per episode and per success, LLM calls per episode (mean and sample sd, as
-- the paper reports them), cached share of prompt tokens and environment steps.
SELECT model_label, arm, env_split,
  count(*) AS episodes,
  count(*) FILTER (WHERE success) AS successes,
  sum(cost_usd) AS cost_usd,
  avg(cost_usd) AS cost_per_episode,
  stddev_samp(cost_usd) AS cost_sd,
  sum(cost_usd) / nullif(count(*) FILTER (WHERE success), 0) AS cost_per_success,
  avg(prompt_tokens) AS prompt_tokens_per_episode,
  avg(completion_tokens) AS completion_tokens_per_episode,
  avg(prompt_tokens + completion_tokens) AS tokens_per_episode,
  sum(prompt_tokens + completion_tokens) / nullif(count(*) FILTER (WHERE success), 0) AS tokens_per_success,
  avg(llm_calls) AS calls_per_episode,
  stddev_samp(llm_calls) AS calls_sd,
  sum(cached_prompt_tokens) / nullif(sum(prompt_tokens), 0) AS cached_share,
  avg(steps) AS steps_per_episode
FROM outcomes
GROUP BY model_label, arm, env_split
ORDER BY env_split, model_label, arm;
