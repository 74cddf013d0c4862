-- Task-tree statistics per model, arm and environment split over the finished units that have a
-- tree (see tree_stats in views.sql for the definitions). mean_levels / mean_max_depth: the
-- tree depth counting the root as level 1 / in edges from the root; mean_branching_factor: the
-- mean over episodes of each episode's mean children per non-leaf node (episodes whose tree is
-- a lone root have no branching factor and are left out of that mean).
SELECT t.model_label, t.arm, t.env_split,
  count(*) AS episodes,
  avg(s.levels) AS mean_levels,
  avg(s.max_depth) AS mean_max_depth,
  stddev_samp(s.max_depth) AS max_depth_sd,
  avg(s.branching_factor) AS mean_branching_factor,
  stddev_samp(s.branching_factor) AS branching_factor_sd,
  max(s.max_children) AS max_children,
  avg(s.nodes) AS nodes_per_episode,
  avg(s.leaf_failures) AS leaf_failures_per_episode,
  sum(s.leaf_failures) AS leaf_failures,
  avg(s.refinements) AS refinements_per_episode
FROM outcomes t
JOIN tree_stats s ON s.run_id = t.run_id AND s.episode_id = t.episode_id
GROUP BY t.model_label, t.arm, t.env_split
ORDER BY t.env_split, t.model_label, t.arm;
