-- Pipeline events (retries, errors, restarts, caps) by source, kind and severity.
SELECT source, kind, severity, count(*) AS events,
  count(DISTINCT episode_id) AS episodes
FROM events
GROUP BY source, kind, severity
ORDER BY events DESC, source, kind, severity;
