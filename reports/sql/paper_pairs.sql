-- Paired comparisons for the paper section: every arm against each ReCAP arm without ablation
-- of the same model (reference = that ReCAP arm), on the units both ran - same benchmark, split,
-- task, instance and seed, units that finished on their own merits (outcomes) - per split and per task
-- (level), and over Robotouille synchronous tasks 2, 4, 6 (scope 'sync_2_4_6', per split only). ref_only / arm_only are the discordant pairs; p_value is the clustered McNemar
-- test (clustered_mcnemar_p: the arms swapped per instance, all its seeds together; the exact McNemar
-- test when every instance ran one seed); instances counts the paired instances; cost_diffs (arm minus
-- reference, in pair order) and cost_instances (each pair's instance, same order) feed the paired
-- permutation test of the cost difference, which flips the signs of whole instances
-- (reports.stats.clustered_permutation_test); arm_cost / ref_cost are the two arms' totals over the paired units.
-- A unit is (run, unit id): two arms that ran one key in several runs pair run by run (shared);
-- the rest pair latest with latest (rep), as in paired_methods.sql.
WITH scoped AS (SELECT * FROM paper_scoped), sides AS (
  -- each unit once per arm it is compared with (an arm against each ReCAP reference, a reference
  -- against each arm), marked when that arm ran the same key in the same run
  SELECT u.*, o.arm_label AS other,
    EXISTS (SELECT 1 FROM scoped s WHERE s.run_id = u.run_id AND s.arm_label = o.arm_label AND s.scope = u.scope
      AND s.model_label = u.model_label AND s.benchmark = u.benchmark AND s.split = u.split AND s.task = u.task
      AND s.instance_id = u.instance_id AND s.sampling_seed = u.sampling_seed) AS shared
  FROM scoped u
  JOIN (SELECT DISTINCT scope, model_label, benchmark, split, task, instance_id, sampling_seed, arm_label,
          method = 'recap' AND variant = 'original' AS is_ref FROM scoped) o
    ON o.scope = u.scope AND o.model_label = u.model_label AND o.benchmark = u.benchmark AND o.split = u.split
   AND o.task = u.task AND o.instance_id = u.instance_id AND o.sampling_seed = u.sampling_seed
   AND o.arm_label <> u.arm_label AND (o.is_ref OR (u.method = 'recap' AND u.variant = 'original'))
), ranked AS (
  SELECT *, row_number() OVER (
    PARTITION BY scope, model_label, benchmark, split, task, instance_id, sampling_seed, arm_label, other
    ORDER BY shared DESC, CASE WHEN shared THEN run_id END DESC, ended_at DESC, run_id DESC, episode_id DESC) AS rep
  FROM sides
), joined AS (
  SELECT a.scope, a.model_label, a.arm_label, r.arm_label AS ref_label, a.benchmark, a.split, a.task,
    a.instance_id, a.sampling_seed, a.run_id, a.success AS a_success, r.success AS r_success, a.cost_usd AS a_cost, r.cost_usd AS r_cost
  FROM ranked a
  JOIN ranked r
    ON r.scope = a.scope AND r.method = 'recap' AND r.variant = 'original' AND r.arm_label <> a.arm_label
   AND r.arm_label = a.other AND a.arm_label = r.other AND r.rep = a.rep
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
  list(a_cost - r_cost ORDER BY task, instance_id, sampling_seed, run_id) AS cost_diffs,
  list(instance_key(benchmark, split, task, instance_id) ORDER BY task, instance_id, sampling_seed, run_id) AS cost_instances
FROM joined
GROUP BY GROUPING SETS ((scope, model_label, arm_label, ref_label, benchmark, split, task), (scope, model_label, arm_label, ref_label, benchmark, split))
HAVING scope = 'all' OR GROUPING(task) = 1
ORDER BY scope, benchmark, split, level, task, model_label, arm_label, ref_label;
