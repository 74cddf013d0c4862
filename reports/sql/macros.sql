-- Statistics and labels as SQL macros, so that report queries and ad-hoc `recap sql` queries
-- compute them the same way.

-- Wilson score interval for k successes out of n at 95% (z = 1.959963984540054); NULL when n = 0.
-- Clamped to [0, 1], and exactly 0 for k = 0 and 1 for k = n (rounding misses both by ~1e-17).
-- k and n may be fractional (the effective sample size of cluster_wilson_low/high).
CREATE MACRO wilson_low(k, n) AS
  CASE WHEN n > 0 AND k <= 0 THEN 0.0 WHEN n > 0 THEN greatest(0.0,
    ((k / n) + 1.959963984540054 ^ 2 / (2 * n)
      - 1.959963984540054 * sqrt(greatest((k / n) * (1 - k / n), 0.0) / n + 1.959963984540054 ^ 2 / (4 * n ^ 2)))
    / (1 + 1.959963984540054 ^ 2 / n))
  END;

CREATE MACRO wilson_high(k, n) AS
  CASE WHEN n > 0 AND k >= n THEN 1.0 WHEN n > 0 THEN least(1.0,
    ((k / n) + 1.959963984540054 ^ 2 / (2 * n)
      + 1.959963984540054 * sqrt(greatest((k / n) * (1 - k / n), 0.0) / n + 1.959963984540054 ^ 2 / (4 * n ^ 2)))
    / (1 + 1.959963984540054 ^ 2 / n))
  END;

-- Several seeds of one instance are not independent trials. kish_deff is Kish's design effect
-- 1 + (m - 1) * rho of a success rate from its per-instance sufficient statistics: g instances,
-- n episodes, k successes, q = sum over instances of y^2 / m (y successes of m episodes), mm =
-- sum of m^2; m = n / g, rho = the one-way ANOVA estimate of the intra-class correlation,
-- truncated at 0. It is 1 when rho cannot be estimated (fewer than two instances, one episode per
-- instance, or no variation). instance_deff(obs) computes it from obs = list({'instance': key,
-- 'success': bool}) (one entry per episode), and cluster_wilson_low/high(obs) are the Wilson
-- bounds at the effective sample size n / deff. Reference implementation and citations:
-- reports/stats.py (design_effect, cluster_wilson); keep the two in step.
CREATE MACRO kish_deff(g, n, k, q, mm) AS
  CASE WHEN g >= 2 AND n > g
        AND (q - k * k / n) / (g - 1) + ((n - mm / n) / (g - 1) - 1) * (k - q) / (n - g) > 0
    THEN 1.0 + (n / g - 1) * greatest(0.0,
      ((q - k * k / n) / (g - 1) - (k - q) / (n - g))
      / ((q - k * k / n) / (g - 1) + ((n - mm / n) / (g - 1) - 1) * (k - q) / (n - g)))
    ELSE 1.0
  END;

-- The instance an episode ran: several seeds of one instance form one cluster.
CREATE MACRO instance_key(benchmark, split, task, instance_id) AS concat_ws('/', benchmark, split, task, instance_id);

-- One episode's entry of obs: its instance (benchmark, split, task, instance id) and its success.
CREATE MACRO episode_obs(benchmark, split, task, instance_id, success) AS
  {'instance': instance_key(benchmark, split, task, instance_id), 'success': success};

-- Per-instance counts of obs: m episodes and y successes per instance (one row per instance).
CREATE MACRO instance_counts(obs) AS TABLE
  SELECT count(*)::DOUBLE AS m, (count(*) FILTER (WHERE o.success))::DOUBLE AS y
  FROM (SELECT unnest(obs) AS o)
  GROUP BY o.instance;

CREATE MACRO instance_deff(obs) AS (
  SELECT kish_deff(count(*)::DOUBLE, sum(m), sum(y), sum(y * y / m), sum(m * m)) FROM instance_counts(obs)
);

-- The Wilson bound at the effective sample: successes and episodes both divided by the design effect.
CREATE MACRO cluster_wilson_low(obs) AS (
  SELECT wilson_low(sum(y) / any_value(d), sum(m) / any_value(d))
  FROM instance_counts(obs), (SELECT instance_deff(obs) AS d)
);

CREATE MACRO cluster_wilson_high(obs) AS (
  SELECT wilson_high(sum(y) / any_value(d), sum(m) / any_value(d))
  FROM instance_counts(obs), (SELECT instance_deff(obs) AS d)
);

-- Exact two-sided McNemar test on the discordant pairs b (only A succeeded) and c (only B):
-- p = min(1, 2 * P[X <= min(b, c)]) with X ~ Binomial(b + c, 1/2). It treats every pair as
-- independent: with several seeds per instance use clustered_mcnemar_p, which equals it when each
-- instance ran one seed.
CREATE MACRO mcnemar_p(b, c) AS (
  SELECT least(1.0, 2 * sum(exp(lgamma(b + c + 1) - lgamma(k + 1) - lgamma(b + c - k + 1) - (b + c) * ln(2))))
  FROM range(0, least(b, c) + 1) AS t(k)
);

-- Exact two-sided sign-flip permutation p-value of integer totals ds (one per instance):
-- P[|sum s_i d_i| >= |sum d_i|] over the 2^k equally likely sign patterns s of the k non-zero
-- totals. The distribution of the signed sum is built by convolution (list index j <-> sum
-- j - 1 - sum |d|), each step halving, so it is exact up to rounding for any k.
CREATE MACRO sign_flip_int_p(ds) AS (
  SELECT least(1.0, list_sum(list_transform(dist, lambda x, j: CASE WHEN abs(j - 1 - h) >= o THEN x ELSE 0.0 END)))
  FROM (
    SELECT list_reduce(
        list_filter(list_transform(ds, lambda d: abs(d)::BIGINT), lambda d: d > 0),
        lambda acc, d: list_transform(range(1, len(acc) + 2 * d + 1),
          lambda j: ((CASE WHEN j <= len(acc) THEN acc[j] ELSE 0.0 END) + (CASE WHEN j > 2 * d THEN acc[j - 2 * d] ELSE 0.0 END)) / 2),
        [1.0]::DOUBLE[]) AS dist,
      coalesce(list_sum(list_transform(ds, lambda d: abs(d))), 0) AS h,
      abs(coalesce(list_sum(ds), 0)) AS o
  )
);

-- One paired unit's entry of a clustered McNemar test: its instance and A's success minus B's
-- (1: only A succeeded, -1: only B, 0: concordant).
CREATE MACRO pair_obs(benchmark, split, task, instance_id, a_success, b_success) AS
  {'instance': instance_key(benchmark, split, task, instance_id), 'd': a_success::INTEGER - b_success::INTEGER};

-- Clustered McNemar test over obs = list(pair_obs(...)) (one entry per paired unit): the exact
-- permutation test that swaps the two arms within each instance, all its seeds together (the
-- signs of the per-instance totals b_i - c_i flipped; the exact form of Durkalski et al.'s
-- clustered McNemar statistic, Statistics in Medicine 22, 2003). One seed per instance gives
-- exactly mcnemar_p(b, c). Reference implementation: reports/stats.py (clustered_mcnemar_exact).
CREATE MACRO clustered_mcnemar_p(obs) AS (
  SELECT sign_flip_int_p(coalesce(list(d), []::BIGINT[]))
  FROM (SELECT sum(o.d)::BIGINT AS d FROM (SELECT unnest(obs) AS o) GROUP BY o.instance)
);

-- "gpt-4o" or "scripted (test double)": every table labels test-double models.
CREATE MACRO model_label(model, test_double) AS
  coalesce(nullif(model, ''), '(unknown model)') || CASE WHEN test_double THEN ' (test double)' ELSE '' END;

-- The infrastructure failure a terminal episode row records ('server_error', 'auth',
-- 'not_found', 'worker_lost', 'client', 'infra' ...), or NULL when the row is a real outcome: the
-- rule of schemas.labels.infra_failure (keep the two in step). Such a unit is not done: resume
-- retries it. Rows of schema version 2 end 'infra_error'; version 1 wrote llm_error/env_error,
-- which the reader maps to 'infra_error' by this same rule.
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
        WHEN end_reason = 'infra_error' THEN 'infra'
      END
    WHEN coalesce(end_reason, '') NOT IN ('llm_error', 'infra_error') THEN NULL
    WHEN trim(split_part(trim(coalesce(error, '')), ':', 1)) IN ('rate_limit', 'timeout', 'server_error', 'auth', 'connection', 'not_found')
      THEN trim(split_part(trim(coalesce(error, '')), ':', 1))
    WHEN trim(split_part(trim(coalesce(error, '')), ':', 1)) = 'bad_request'
         AND regexp_matches(coalesce(error, ''), 'NotFoundError|\b404\b|[Nn]ot [Ff]ound')
      THEN 'not_found'
    WHEN end_reason = 'infra_error' THEN 'infra'
  END;
