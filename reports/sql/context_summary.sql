-- Context bound summary per model and arm (successful calls of latest attempts): prompt tokens per
-- call (mean, median, 95th percentile, max), the largest window in messages, and how fast the
-- prompt still grows once the window is full, measured per episode:
--   * an episode's window has filled when its largest window (messages) reaches the arm's window
--     size K (method_config.window); it fills at the first call with that largest window;
--   * its growth is the least-squares slope of prompt tokens over call_index on the calls from
--     that call on (tokens added per call; near 0 when the context is bounded), kept when at
--     least 2 calls follow the fill;
--   * the arm's figure is the median of those per-episode slopes with their interquartile range
--     (25th and 75th percentiles), over filled_episodes episodes.
-- Pooling every call of every episode into one regression would mix the growth before the window
-- fills (which every method has) with the bounded part, and weight long episodes more.
WITH ok AS (
  SELECT c.model_label, c.arm, c.run_id, c.episode_id, c.call_index, c.prompt_tokens, c.window_len, a.window_size
  FROM calls c
  LEFT JOIN attempts a ON a.run_id = c.run_id AND a.episode_id = c.episode_id
  WHERE c.status = 'ok' AND c.latest_attempt
), per_episode AS (
  SELECT model_label, arm, run_id, episode_id, any_value(window_size) AS window_size, max(window_len) AS full_len
  FROM ok
  GROUP BY ALL
), filled AS (
  SELECT o.model_label, o.arm, o.run_id, o.episode_id, min(o.call_index) AS fill_index
  FROM ok o
  JOIN per_episode e
    ON e.model_label = o.model_label AND e.arm = o.arm AND e.run_id = o.run_id AND e.episode_id = o.episode_id
  WHERE e.full_len >= e.window_size AND o.window_len = e.full_len
  GROUP BY ALL
), slopes AS (
  SELECT o.model_label, o.arm, o.run_id, o.episode_id, regr_slope(o.prompt_tokens, o.call_index) AS slope
  FROM ok o
  JOIN filled f
    ON f.model_label = o.model_label AND f.arm = o.arm AND f.run_id = o.run_id AND f.episode_id = o.episode_id
  WHERE o.call_index >= f.fill_index
  GROUP BY ALL
  HAVING count(*) >= 2
), growth AS (
  SELECT model_label, arm,
    count(*) AS filled_episodes,
    quantile_cont(slope, 0.5) AS slope_median,
    quantile_cont(slope, 0.25) AS slope_q25,
    quantile_cont(slope, 0.75) AS slope_q75
  FROM slopes
  GROUP BY ALL
), per_call AS (
  SELECT model_label, arm,
    count(DISTINCT (run_id, episode_id)) AS episodes,
    count(*) AS calls,
    avg(prompt_tokens) AS mean_prompt_tokens,
    quantile_cont(prompt_tokens, 0.5) AS median_prompt_tokens,
    quantile_cont(prompt_tokens, 0.95) AS p95_prompt_tokens,
    max(prompt_tokens) AS max_prompt_tokens,
    max(window_len) AS max_window_messages
  FROM ok
  GROUP BY ALL
)
SELECT p.model_label, p.arm, p.episodes, p.calls, p.mean_prompt_tokens, p.median_prompt_tokens,
  p.p95_prompt_tokens, p.max_prompt_tokens, p.max_window_messages,
  coalesce(g.filled_episodes, 0) AS filled_episodes, g.slope_median, g.slope_q25, g.slope_q75
FROM per_call p
LEFT JOIN growth g ON g.model_label = p.model_label AND g.arm = p.arm
ORDER BY p.model_label, p.arm;
