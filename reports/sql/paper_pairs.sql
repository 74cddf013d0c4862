-- Paired comparisons for the paper section: every arm against each ReCAP arm without ablation
-- of the same model (reference = that ReCAP arm), on the units both ran - same benchmark, split,
-- task, instance and seed, units that finished on their own merits (outcomes) - per split and per task
-- (level), and over Robotouille synchronous tasks 2, 4, 6 (scope 'sync_2_4_6', per split only). ref_only / arm_only are the discordant pairs; p_value is the clustered McNemar
-- test (clustered_mcnemar_p: the arms swapped per instance, all its seeds together; the exact McNemar
-- test when every instance ran one seed); instances counts the paired instances; cost_diffs (arm minus
-- reference, in pair order) and cost_instances (each pair's instance, same order) feed the paired
-- permutation test of the cost difference, which flips the signs of whole instances
-- (reports.stats.clustered_permutation_test); arm_cost / ref_cost are the two arms' totals over the paired units.
WITH scoped AS (SELECT * FROM paper_scoped), joined AS (
  SELECT a.scope, a.model_label, a.arm_label, r.arm_label AS ref_label, a.benchmark, a.split, a.task,
    a.instance_id, a.sampling_seed, a.success AS a_success, r.success AS r_success, a.cost_usd AS a_cost, r.cost_usd AS r_cost
  FROM scoped a
  JOIN scoped r
    ON r.scope = a.scope AND r.method = 'recap' AND r.variant = 'original' AND r.arm_label <> a.arm_label
   AND r.model_label = a.model_label AND r.benchmark = a.benchmark AND r.split = a.split
   AND r.task = a.task AND r.instance_id = a.instance_id AND r.sampling_seed = a.sampling_seed
)
SELECT scope, model_label, arm_label, ref_label, benchmark, split,
  CASE WHEN GROUPING(task) = 1 THEN 'split' ELSE 'task' END AS level, task,
  count(*) AS pairs,
  count(*) FILTER (WHERE r_success AND NOT a_success) AS ref_only,
  count(*) FILTER (WHERE a_success AND NOT r_success) AS arm_only,
  count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances,
  clustered_mcnemar_p(list(pair_obs(benchmark, split, task, instance_id, a_success, r_success))) AS p_value,
  sum(a_cost) AS arm_cost, sum(r_cost) AS ref_cost,
  list(a_cost - r_cost ORDER BY task, instance_id, sampling_seed) AS cost_diffs,
  list(instance_key(benchmark, split, task, instance_id) ORDER BY task, instance_id, sampling_seed) AS cost_instances
FROM joined
GROUP BY GROUPING SETS ((scope, model_label, arm_label, ref_label, benchmark, split, task), (scope, model_label, arm_label, ref_label, benchmark, split))
HAVING scope = 'all' OR GROUPING(task) = 1
ORDER BY scope, benchmark, split, level, task, model_label, arm_label, ref_label;
