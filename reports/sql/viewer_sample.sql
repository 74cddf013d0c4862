-- Episodes shown in the viewer when none are named, up to $n: taking turns over (model, arm) and
-- failure modes, so the sample covers every method before it repeats one: first each method's
-- success, then each method's first failure mode (modes in name order), and so on.
WITH ranked AS (
  SELECT run_id, episode_id, mode, model_label, arm,
    row_number() OVER (PARTITION BY model_label, arm, mode ORDER BY episode_id, run_id) AS nth
  FROM episode_modes
), turns AS (
  SELECT *,
    row_number() OVER (PARTITION BY model_label, arm, nth ORDER BY mode <> 'success', mode) AS turn
  FROM ranked
)
SELECT run_id, episode_id
FROM turns
ORDER BY nth, turn, model_label, arm, episode_id
LIMIT $n;
