-- Spend that bought no success, per model and arm, over every LLM call of every attempt:
--   failed_call_cost    calls that ended in an error (their provider retries are counted in retries)
--   repair_cost         JSON-repair calls (purpose 'repair': re-asks after a malformed reply)
--   superseded_cost     calls of attempts that were later re-run (not the unit's latest attempt)
--   orphan_cost         calls whose attempt has no episode row (lost with a worker)
--   failed_episode_cost calls of latest attempts that did not succeed
--   wasted_cost         everything except the calls of successful latest attempts
-- Calls without an episode row have arm '(no episode row)'.
SELECT model_label,
  coalesce(arm, '(no episode row)') AS arm,
  count(*) AS calls,
  sum(cost_usd) AS cost_usd,
  count(*) FILTER (WHERE status = 'error') AS failed_calls,
  sum(retries) AS retries,
  coalesce(sum(cost_usd) FILTER (WHERE status = 'error'), 0) AS failed_call_cost,
  count(*) FILTER (WHERE purpose = 'repair') AS repair_calls,
  coalesce(sum(cost_usd) FILTER (WHERE purpose = 'repair'), 0) AS repair_cost,
  coalesce(sum(cost_usd) FILTER (WHERE latest_attempt = false), 0) AS superseded_cost,
  coalesce(sum(cost_usd) FILTER (WHERE latest_attempt IS NULL), 0) AS orphan_cost,
  coalesce(sum(cost_usd) FILTER (WHERE latest_attempt AND NOT episode_success), 0) AS failed_episode_cost,
  coalesce(sum(cost_usd) FILTER (WHERE latest_attempt IS NOT TRUE OR NOT episode_success), 0) AS wasted_cost,
  coalesce(sum(cost_usd) FILTER (WHERE latest_attempt IS NOT TRUE OR NOT episode_success), 0)
    / nullif(sum(cost_usd), 0) AS wasted_share
FROM calls
GROUP BY model_label, coalesce(arm, '(no episode row)')
ORDER BY model_label, arm;
