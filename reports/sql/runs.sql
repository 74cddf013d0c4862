-- The runs in the report: starts and resumes (run table), where they ran, and their units.
WITH starts AS (
  SELECT run_id,
    count(*) AS starts,
    min(started_at) AS first_started_at,
    arg_max(host, started_at) AS host,
    arg_max(git_revision, started_at) AS git_revision,
    arg_max(spec_hash, started_at) AS spec_hash,
    arg_max(schema_version, started_at) AS schema_version
  FROM run GROUP BY run_id
), units AS (
  SELECT run_id, count(*) AS units, count(*) FILTER (WHERE success) AS successes
  FROM terminal GROUP BY run_id
)
SELECT coalesce(s.run_id, u.run_id) AS run_id,
  coalesce(s.starts, 0) AS starts,
  strftime(make_timestamp(CAST(s.first_started_at * 1000000 AS BIGINT)), '%Y-%m-%d %H:%M:%S UTC') AS first_started,
  s.host, s.git_revision, s.spec_hash, s.schema_version,
  coalesce(u.units, 0) AS units,
  coalesce(u.successes, 0) AS successes
FROM starts s FULL OUTER JOIN units u ON u.run_id = s.run_id
ORDER BY run_id;
