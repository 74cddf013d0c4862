-- Coverage: per run and arm (method label x model of the sweep), the units planned and where each
-- stands: finished (a terminal row that is neither budget_exhausted nor an infrastructure
-- failure - env_error and llm_error outcomes count), capped (no such row, the latest one is
-- budget_exhausted), infra_failed (no such row, the latest one is an infrastructure failure:
-- retried by recap resume), not_started (no terminal row). The same rules as recap status.
-- planned_from: 'plan.json' when the run folder's plan was read (planned_units), else
-- 'episode rows' - planned is then only the units that have a row (never-started units unknown).
WITH planned_runs AS (
  SELECT DISTINCT run_id FROM planned_units
), rows AS (
  SELECT run_id, unit_id, attempt, ended_at, episode_id, end_reason, success, method, model, test_double,
    infra_failure_kind(end_reason, error) AS infra_kind
  FROM episodes
), seen AS (
  SELECT run_id, unit_id, arg_max(method, attempt) AS method, arg_max(model, attempt) AS model
  FROM rows WHERE run_id NOT IN (SELECT run_id FROM planned_runs WHERE run_id IS NOT NULL)
  GROUP BY run_id, unit_id
), units AS (
  SELECT run_id, unit_id, method, model, test_double, 'plan.json' AS planned_from FROM planned_units
  UNION ALL
  SELECT run_id, unit_id, method, model, NULL, 'episode rows' FROM seen
), latest AS (
  SELECT * FROM (
    SELECT r.*, row_number() OVER (PARTITION BY run_id, unit_id ORDER BY attempt DESC, ended_at DESC, episode_id DESC) AS rn
    FROM rows r) WHERE rn = 1
), final AS (
  SELECT * FROM (
    SELECT r.*, row_number() OVER (PARTITION BY run_id, unit_id ORDER BY attempt DESC, ended_at DESC, episode_id DESC) AS rn
    FROM rows r WHERE end_reason <> 'budget_exhausted' AND infra_kind IS NULL) WHERE rn = 1
), doubles AS (
  SELECT run_id, model, bool_or(test_double) AS test_double FROM episodes GROUP BY run_id, model
)
SELECT u.run_id,
  model_label(u.model, coalesce(u.test_double, d.test_double, false)) AS model_label,
  u.method,
  count(*) AS planned,
  count(f.unit_id) AS finished,
  count(*) FILTER (WHERE f.success) AS successes,
  count(*) FILTER (WHERE f.unit_id IS NULL AND l.end_reason = 'budget_exhausted') AS capped,
  count(*) FILTER (WHERE f.unit_id IS NULL AND l.unit_id IS NOT NULL AND l.end_reason <> 'budget_exhausted') AS infra_failed,
  count(*) FILTER (WHERE l.unit_id IS NULL) AS not_started,
  min(u.planned_from) AS planned_from
FROM units u
LEFT JOIN final f ON f.run_id IS NOT DISTINCT FROM u.run_id AND f.unit_id = u.unit_id
LEFT JOIN latest l ON l.run_id IS NOT DISTINCT FROM u.run_id AND l.unit_id = u.unit_id
LEFT JOIN doubles d ON d.run_id IS NOT DISTINCT FROM u.run_id AND d.model = u.model
GROUP BY ALL
ORDER BY 1, 2, 3;
