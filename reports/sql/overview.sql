-- One row describing what the report covers.
SELECT
  (SELECT count(*) FROM run_dirs) AS run_folders,
  (SELECT count(DISTINCT run_id) FROM episodes) AS runs,
  (SELECT count(*) FROM episodes) AS attempts,
  (SELECT count(*) FROM terminal) AS units,
  (SELECT count(*) FROM outcomes) AS finished_units,
  (SELECT count(*) FILTER (WHERE success) FROM outcomes) AS successes,
  (SELECT count(*) FILTER (WHERE test_double) FROM terminal) AS test_double_units,
  (SELECT count(*) FROM llm_calls) AS llm_calls,
  (SELECT coalesce(sum(cost_usd), 0) FROM llm_calls) AS spend_usd,
  (SELECT count(*) FROM steps) AS steps,
  (SELECT count(*) FROM bad_parts) AS skipped_part_files;
