-- The paper section's cells: one row per arm (model label x arm label) and benchmark split, and
-- one per arm and task (level = 'split' / 'task'); scope 'sync_2_4_6' adds one row per arm over
-- Robotouille synchronous tasks 2, 4 and 6 only (the cross-model table's tasks); over the units counted for success rates: the
-- units that finished on their own merits (the outcomes view: neither capped by a budget nor an
-- infrastructure failure). Besides the success counts (95% Wilson bounds widened by the design
-- effect of several seeds per instance: cluster_wilson_low/high in macros.sql) each row carries
-- what the arm ran (provider model, test double, profile, windows, step multipliers, tasks), so
-- the section can decide whether a paper number is comparable, and the cost totals.
WITH scoped AS (SELECT * FROM paper_scoped), cells AS (
  SELECT scope, model_label, arm_label, benchmark, split, task,
    CASE WHEN GROUPING(task) = 1 THEN 'split' ELSE 'task' END AS level,
    any_value(method) AS method, any_value(variant) AS ablation,
    list(DISTINCT profile ORDER BY profile) AS profiles,
    list(DISTINCT provider_model ORDER BY provider_model) AS provider_models,
    bool_or(test_double) AS test_double,
    list(DISTINCT window_size ORDER BY window_size) AS windows,
    count(*) AS episodes,
    count(*) FILTER (WHERE success) AS successes,
    cluster_wilson_low(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_low,
    cluster_wilson_high(list(episode_obs(benchmark, split, task, instance_id, success))) AS ci_high,
    instance_deff(list(episode_obs(benchmark, split, task, instance_id, success))) AS deff,
    count(DISTINCT instance_key(benchmark, split, task, instance_id)) AS instances,
    sum(cost_usd) AS cost_usd,
    avg(cost_usd) AS cost_per_episode,
    stddev_samp(cost_usd) AS cost_sd,
    sum(llm_calls) AS calls,
    avg(llm_calls) AS calls_per_episode,
    stddev_samp(llm_calls) AS calls_sd,
    sum(prompt_tokens + completion_tokens) AS tokens,
    avg(prompt_tokens + completion_tokens) AS tokens_per_episode
  FROM scoped
  GROUP BY GROUPING SETS ((scope, model_label, arm_label, benchmark, split, task), (scope, model_label, arm_label, benchmark, split))
  HAVING scope = 'all' OR GROUPING(task) = 1
), task_mults AS (
  SELECT scope, model_label, arm_label, benchmark, split, task, list(DISTINCT step_multiplier ORDER BY step_multiplier) AS mults
  FROM scoped GROUP BY ALL
), protocol AS (
  SELECT scope, model_label, arm_label, benchmark, split,
    list({'task': task, 'multipliers': mults} ORDER BY task) AS task_multipliers
  FROM task_mults GROUP BY ALL
)
SELECT c.scope, c.model_label, c.arm_label, c.method, c.ablation, c.benchmark, c.split, c.level, c.task,
  c.profiles, c.provider_models, c.test_double, c.windows,
  CASE WHEN c.level = 'split' THEN p.task_multipliers
       ELSE list_filter(p.task_multipliers, lambda x: x.task = c.task) END AS task_multipliers,
  c.episodes, c.successes, c.successes / c.episodes AS success_rate, c.ci_low, c.ci_high, c.instances, c.deff,
  c.cost_usd, c.cost_per_episode, c.cost_sd, c.calls, c.calls_per_episode, c.calls_sd, c.tokens, c.tokens_per_episode
FROM cells c
JOIN protocol p USING (scope, model_label, arm_label, benchmark, split)
ORDER BY c.scope, c.benchmark, c.split, c.level, c.task, c.model_label, c.arm_label;
