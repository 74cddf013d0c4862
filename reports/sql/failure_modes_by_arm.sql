-- Failure modes per model and arm (finished units): episodes in each mode, their share of the arm's episodes and
-- their cost.
SELECT model_label, arm, mode,
  count(*) AS episodes,
  count(*) / sum(count(*)) OVER (PARTITION BY model_label, arm) AS share,
  sum(cost_usd) AS cost_usd
FROM episode_modes
WHERE state = 'finished'
GROUP BY model_label, arm, mode
ORDER BY model_label, arm, episodes DESC, mode;
