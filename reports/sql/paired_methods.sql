-- Paired comparisons: every two arms of the same model and environment split, on the units both
-- finished (same task, instance and seed; the outcomes view). a_only / b_only are the discordant pairs;
-- p_value is the clustered McNemar test (clustered_mcnemar_p: the arms swapped per instance, all its
-- seeds together; the exact McNemar test when every instance ran one seed); instances counts the
-- paired instances. cost_diffs (arm_a minus arm_b, per pair, in pair order) and cost_instances (each
-- pair's instance, same order) feed the paired permutation test of the mean cost difference, which
-- flips the signs of whole instances (reports.stats.clustered_permutation_test).
-- A unit is (run, unit id): runs read together that both ran the two arms give one pair per run
-- (the two arms' units of one run paired: shared first, run by run); units left without a partner
-- in their own run pair with the other arm's leftovers of other runs, latest with latest (rep).
WITH per_unit AS (
  SELECT run_id, model_label, env_split, arm, benchmark, split, task, instance_id, sampling_seed,
    arg_max(success, ended_at) AS success,
    arg_max(cost_usd, ended_at) AS cost_usd,
    max(ended_at) AS ended_at
  FROM outcomes
  GROUP BY ALL
), sides AS (
  SELECT u.*, o.arm AS other, s.run_id IS NOT NULL AS shared
  FROM per_unit u
  JOIN (SELECT DISTINCT model_label, env_split, benchmark, split, task, instance_id, sampling_seed, arm FROM per_unit) o
    ON o.model_label = u.model_label AND o.env_split = u.env_split AND o.benchmark = u.benchmark AND o.split = u.split
   AND o.task = u.task AND o.instance_id = u.instance_id AND o.sampling_seed = u.sampling_seed AND o.arm <> u.arm
  LEFT JOIN per_unit s
    ON s.run_id = u.run_id AND s.arm = o.arm AND s.model_label = u.model_label AND s.env_split = u.env_split
   AND s.benchmark = u.benchmark AND s.split = u.split AND s.task = u.task AND s.instance_id = u.instance_id
   AND s.sampling_seed = u.sampling_seed
), ranked AS (
  SELECT *, row_number() OVER (
    PARTITION BY model_label, env_split, benchmark, split, task, instance_id, sampling_seed, arm, other
    ORDER BY shared DESC, CASE WHEN shared THEN run_id END DESC, ended_at DESC, run_id DESC) AS rep
  FROM sides
), counted AS (
  SELECT a.model_label, a.env_split, a.arm AS arm_a, b.arm AS arm_b,
    count(*) AS pairs,
    count(*) FILTER (WHERE a.success) AS a_successes,
    count(*) FILTER (WHERE b.success) AS b_successes,
    count(*) FILTER (WHERE a.success AND NOT b.success) AS a_only,
    count(*) FILTER (WHERE b.success AND NOT a.success) AS b_only,
    count(DISTINCT instance_key(a.benchmark, a.split, a.task, a.instance_id)) AS instances,
    clustered_mcnemar_p(list(pair_obs(a.benchmark, a.split, a.task, a.instance_id, a.success, b.success))) AS p_value,
    avg(a.cost_usd - b.cost_usd) AS mean_cost_diff,
    list(a.cost_usd - b.cost_usd ORDER BY a.task, a.instance_id, a.sampling_seed, a.run_id) AS cost_diffs,
    list(instance_key(a.benchmark, a.split, a.task, a.instance_id) ORDER BY a.task, a.instance_id, a.sampling_seed, a.run_id) AS cost_instances
  FROM ranked a
  JOIN ranked b
    ON a.model_label = b.model_label AND a.env_split = b.env_split AND a.arm < b.arm
   AND b.arm = a.other AND a.arm = b.other AND a.rep = b.rep
   AND a.benchmark = b.benchmark AND a.split = b.split
   AND a.task = b.task AND a.instance_id = b.instance_id AND a.sampling_seed = b.sampling_seed
  GROUP BY a.model_label, a.env_split, a.arm, b.arm
)
SELECT model_label, env_split, arm_a, arm_b, pairs, a_successes, b_successes,
  (a_successes - b_successes) / pairs AS rate_diff,
  a_only, b_only, instances, p_value,
  mean_cost_diff, cost_diffs, cost_instances
FROM counted
ORDER BY env_split, model_label, arm_a, arm_b;
