-- Task-tree statistics for the paper section: per arm, over the units that finished on their own merits (outcomes)
-- of Robotouille synchronous task 6 that have a tree. levels = deepest node + 1 (root = level 1,
-- the convention of the level_N ablations); branching = mean children per node with children
-- (tree_stats in views.sql); per-episode values, averaged, with sample sd.
WITH counted AS (
  SELECT *, coalesce(nullif(arm, ''), method) AS arm_label, ablation AS variant FROM outcomes
)
SELECT c.model_label, c.arm_label, any_value(c.method) AS method, any_value(c.variant) AS ablation,
  c.benchmark, c.split, c.task,
  list(DISTINCT c.profile ORDER BY c.profile) AS profiles,
  list(DISTINCT c.provider_model ORDER BY c.provider_model) AS provider_models,
  bool_or(c.test_double) AS test_double,
  list(DISTINCT c.window_size ORDER BY c.window_size) AS windows,
  list(DISTINCT c.step_multiplier ORDER BY c.step_multiplier) AS multipliers,
  count(*) AS episodes,
  avg(s.levels) AS mean_levels, stddev_samp(s.levels) AS levels_sd,
  avg(s.branching_factor) AS mean_branching, stddev_samp(s.branching_factor) AS branching_sd
FROM counted c
JOIN tree_stats s ON s.run_id = c.run_id AND s.episode_id = c.episode_id
WHERE c.benchmark = 'robotouille' AND c.split = 'synchronous' AND starts_with(c.task, '6_')
GROUP BY c.model_label, c.arm_label, c.benchmark, c.split, c.task
ORDER BY c.model_label, c.arm_label;
