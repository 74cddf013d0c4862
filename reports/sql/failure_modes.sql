-- Failure modes (taxonomy in episode_modes, views.sql) per model over the finished units:
-- episodes, share of the model's episodes, what they cost, mean steps and calls, and up to three
-- example episode ids (smallest ids first).
SELECT model_label, mode,
  count(*) AS episodes,
  count(*) / sum(count(*)) OVER (PARTITION BY model_label) AS share,
  sum(cost_usd) AS cost_usd,
  avg(steps) AS mean_steps,
  avg(llm_calls) AS mean_calls,
  list(episode_id ORDER BY episode_id)[1:3] AS examples
FROM episode_modes
WHERE state = 'finished'
GROUP BY model_label, mode
ORDER BY model_label, episodes DESC, mode;
