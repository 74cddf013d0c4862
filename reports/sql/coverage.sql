-- Coverage: per run and arm (the arm's label x model of the sweep), the units planned and where
-- each stands - the rule of recap status, so the two agree on the same run:
--   finished     a row that finished on its own merits (neither budget_exhausted nor an
--                infrastructure failure; env_error and llm_error outcomes finish) - the units
--                every success rate counts (the outcomes view); successes among them
--   capped       no such row, the latest one ended budget_exhausted (a cap stopped it)
--   gave_up      no such row, the latest one is an infrastructure failure (infra_error: the
--                model service failed, or the driver gave up after its workers died); recap
--                resume retries it
--   not_started  no episode row at all
-- planned_from: 'plan.json' when the run folder's plan was read (planned_units), else
-- 'episode rows' - planned is then only the units that have a row (never-started units unknown).
WITH planned_runs AS (
  SELECT DISTINCT run_id FROM planned_units
), unit_rows AS (
  -- the unit's counted row within its run (is_unit_row's rule, per run)
  SELECT * FROM (
    SELECT a.*, row_number() OVER (
      PARTITION BY a.run_id, a.unit_id ORDER BY a.finished DESC, a.attempt DESC, a.ended_at DESC, a.episode_id DESC) AS rn
    FROM attempts a) WHERE rn = 1
), seen AS (
  SELECT run_id, unit_id, label, method, model
  FROM unit_rows WHERE run_id NOT IN (SELECT run_id FROM planned_runs WHERE run_id IS NOT NULL)
), units AS (
  SELECT run_id, unit_id, label, method, model, test_double, 'plan.json' AS planned_from FROM planned_units
  UNION ALL
  SELECT run_id, unit_id, label, method, model, NULL, 'episode rows' FROM seen
), doubles AS (
  SELECT run_id, model, bool_or(test_double) AS test_double FROM episodes GROUP BY run_id, model
)
SELECT u.run_id,
  model_label(u.model, coalesce(u.test_double, d.test_double, false)) AS model_label,
  u.label AS arm,
  coalesce(min(u.method), min(r.method)) AS method,
  count(*) AS planned,
  count(*) FILTER (WHERE r.finished) AS finished,
  count(*) FILTER (WHERE r.finished AND r.success) AS successes,
  count(*) FILTER (WHERE r.unit_id IS NOT NULL AND NOT r.finished AND r.end_reason = 'budget_exhausted') AS capped,
  count(*) FILTER (WHERE r.unit_id IS NOT NULL AND NOT r.finished AND r.end_reason <> 'budget_exhausted') AS gave_up,
  count(*) FILTER (WHERE r.unit_id IS NULL) AS not_started,
  min(u.planned_from) AS planned_from
FROM units u
LEFT JOIN unit_rows r ON r.run_id IS NOT DISTINCT FROM u.run_id AND r.unit_id = u.unit_id
LEFT JOIN doubles d ON d.run_id IS NOT DISTINCT FROM u.run_id AND d.model = u.model
GROUP BY u.run_id, model_label(u.model, coalesce(u.test_double, d.test_double, false)), u.label
ORDER BY 1, 2, 3;
