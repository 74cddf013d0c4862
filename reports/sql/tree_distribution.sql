-- Distributions of per-episode tree statistics (finished units with a tree), per model and arm:
-- metric 'levels' (root = level 1), 'branching_factor' (floored to an integer bin [k, k+1)) and
-- 'leaf_failures'; value is the bin, episodes the count.
WITH s AS (
  SELECT t.model_label, t.arm, s.levels, s.branching_factor, s.leaf_failures
  FROM outcomes t
  JOIN tree_stats s ON s.run_id = t.run_id AND s.episode_id = t.episode_id
)
SELECT model_label, arm, 'levels' AS metric, CAST(levels AS BIGINT) AS value, count(*) AS episodes
FROM s GROUP BY ALL
UNION ALL
SELECT model_label, arm, 'branching_factor', CAST(floor(branching_factor) AS BIGINT), count(*)
FROM s WHERE branching_factor IS NOT NULL GROUP BY ALL
UNION ALL
SELECT model_label, arm, 'leaf_failures', CAST(leaf_failures AS BIGINT), count(*)
FROM s GROUP BY ALL
ORDER BY metric, model_label, arm, value;
