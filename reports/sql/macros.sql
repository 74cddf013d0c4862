-- Statistics and labels as SQL macros, so that report queries and ad-hoc `recap sql` queries
-- compute them the same way.

-- Wilson score interval for k successes out of n at 95% (z = 1.959963984540054); NULL when n = 0.
CREATE MACRO wilson_low(k, n) AS
  CASE WHEN n > 0 THEN
    ((k / n) + 1.959963984540054 ^ 2 / (2 * n)
      - 1.959963984540054 * sqrt((k / n) * (1 - k / n) / n + 1.959963984540054 ^ 2 / (4 * n ^ 2)))
    / (1 + 1.959963984540054 ^ 2 / n)
  END;

CREATE MACRO wilson_high(k, n) AS
  CASE WHEN n > 0 THEN
    ((k / n) + 1.959963984540054 ^ 2 / (2 * n)
      + 1.959963984540054 * sqrt((k / n) * (1 - k / n) / n + 1.959963984540054 ^ 2 / (4 * n ^ 2)))
    / (1 + 1.959963984540054 ^ 2 / n)
  END;

-- Exact two-sided McNemar test on the discordant pairs b (only A succeeded) and c (only B):
-- p = min(1, 2 * P[X <= min(b, c)]) with X ~ Binomial(b + c, 1/2). For binary outcomes this is
-- also the exact paired permutation (sign-flip) test of the difference in success counts.
CREATE MACRO mcnemar_p(b, c) AS (
  SELECT least(1.0, 2 * sum(exp(lgamma(b + c + 1) - lgamma(k + 1) - lgamma(b + c - k + 1) - (b + c) * ln(2))))
  FROM range(0, least(b, c) + 1) AS t(k)
);

-- "gpt-4o" or "scripted (test double)": every table labels test-double models.
CREATE MACRO model_label(model, test_double) AS
  coalesce(nullif(model, ''), '(unknown model)') || CASE WHEN test_double THEN ' (test double)' ELSE '' END;

-- The infrastructure failure a terminal episode row records ('server_error', 'auth',
-- 'not_found', 'worker_lost', 'client' ...), or NULL when the row is a real outcome: the rule of
-- pipeline.resume.infra_failure (keep the two in step). Such a unit is not done: resume retries it.
CREATE MACRO infra_failure_kind(end_reason, error) AS
  CASE
    WHEN starts_with(trim(coalesce(error, '')), 'gave up after') THEN
      CASE
        WHEN regexp_matches(error, '\(infrastructure: \w+\)') THEN regexp_extract(error, '\(infrastructure: (\w+)\)', 1)
        WHEN starts_with(trim(CASE WHEN contains(error, '; last:') THEN substr(error, position('; last:' IN error) + 7) ELSE '' END), 'client:')
          THEN 'client'
        WHEN regexp_matches(CASE WHEN contains(error, '; last:') THEN substr(error, position('; last:' IN error) + 7) ELSE '' END,
                            'ActorDiedError|RayActorError|ActorUnavailableError|WorkerCrashedError|worker lost')
          THEN 'worker_lost'
      END
    WHEN coalesce(end_reason, '') <> 'llm_error' THEN NULL
    WHEN trim(split_part(trim(coalesce(error, '')), ':', 1)) IN ('rate_limit', 'timeout', 'server_error', 'auth', 'connection', 'not_found')
      THEN trim(split_part(trim(coalesce(error, '')), ':', 1))
    WHEN trim(split_part(trim(coalesce(error, '')), ':', 1)) = 'bad_request'
         AND regexp_matches(coalesce(error, ''), 'NotFoundError|\b404\b|[Nn]ot [Ff]ound')
      THEN 'not_found'
  END;
