-- Named views over the raw tables (episodes, llm_calls, messages, tree_nodes, steps, tool_calls, events, run).
-- Every report query is written against these; they are also there for short ad-hoc queries
-- (`recap sql RUN "SELECT mode, count(*) FROM failures GROUP BY ALL"`).
-- Rows of different runs are told apart by run_id; episodes join their rows on (run_id, episode_id).

-- attempts: every episode row (one per attempt at a unit) with the labels the tables group by.
-- The episode columns are schema version 2 (runs written under version 1 are mapped on read:
-- schemas/versions.py): method = the method's name, label = the arm's label in the sweep,
-- profile, ablation, model = the model's label, provider_model = the model string.
--   ablation     episodes.ablation, 'original' when NULL (the original method): no_think,
--                think_many, name_only, level_N, no_shortcut (several joined with '+').
--   window_size  method_config.window (messages kept in the LLM context).
--   arm          the arm's label, plus ' ctx N' when the same label appears with several window
--                sizes on one benchmark in the data (several runs in one report). A window that
--                differs only from one benchmark to another is the protocol's, not a variant (the
--                released ReAct keeps 64 messages on Robotouille, 128 on ALFWorld): one arm.
--   model_label  the model, with ' (test double)' for test-double models.
--   env_split    benchmark/split: robotouille/synchronous, robotouille/asynchronous,
--                alfworld/valid_unseen (ALFWorld is one split; its task types are the tasks).
--   infra_kind   the infrastructure failure the row records (infra_failure_kind), else NULL.
--   finished     the attempt finished on its own merits: not cut by a cap (budget_exhausted)
--                and not an infrastructure failure. env_error / llm_error outcomes finish.
--   is_latest    the latest attempt of its unit (highest attempt; ties: latest ended_at,
--                episode_id). A unit is (run_id, unit_id): runs read together that share unit
--                ids (the same sweep run twice) are separate units each, never one another's
--                attempts (a resumed run keeps its run_id, so its retries stay attempts).
--   is_unit_row  the row the unit is counted by, the rule of recap status: its latest finished
--                attempt, else its latest attempt.
CREATE VIEW attempts AS
WITH parsed AS (
  SELECT e.*,
    CASE WHEN json_valid(e.method_config) THEN e.method_config END AS _cfg
  FROM episodes e
), settings AS (
  SELECT p.* EXCLUDE (_cfg, ablation),
    TRY_CAST(json_extract_string(_cfg, '$.window') AS BIGINT) AS window_size,
    coalesce(p.ablation, 'original') AS ablation,
    infra_failure_kind(p.end_reason, p.error) AS infra_kind
  FROM parsed p
), marked AS (
  SELECT s.*,
    s.end_reason <> 'budget_exhausted' AND s.infra_kind IS NULL AS finished,
    count(DISTINCT s.window_size) OVER (PARTITION BY s.label, s.benchmark) AS _windows_here
  FROM settings s
)
SELECT s.* EXCLUDE (_windows_here),
  model_label(s.model, s.test_double) AS model_label,
  s.benchmark || '/' || s.split AS env_split,
  s.label
    || CASE WHEN max(s._windows_here) OVER (PARTITION BY s.label) > 1
            THEN ' ctx ' || coalesce(CAST(s.window_size AS VARCHAR), '?') ELSE '' END AS arm,
  row_number() OVER (
    PARTITION BY s.run_id, s.unit_id ORDER BY s.attempt DESC, s.ended_at DESC, s.episode_id DESC
  ) = 1 AS is_latest,
  row_number() OVER (
    PARTITION BY s.run_id, s.unit_id ORDER BY s.finished DESC, s.attempt DESC, s.ended_at DESC, s.episode_id DESC
  ) = 1 AS is_unit_row
FROM marked s;

-- terminal: one row per unit that has an episode row (is_unit_row), with where it stands:
--   state  'finished' (it finished on its own merits), 'capped' (its latest attempt ended
--          budget_exhausted), 'gave_up' (its latest attempt is an infrastructure failure, the
--          driver's give-up after worker deaths included; recap resume retries it).
-- Units without any row are 'not started'; the coverage table counts them from plan.json.
CREATE VIEW terminal AS
SELECT * EXCLUDE (is_unit_row),
  CASE WHEN finished THEN 'finished' WHEN end_reason = 'budget_exhausted' THEN 'capped' ELSE 'gave_up' END AS state
FROM attempts WHERE is_unit_row;

-- outcomes: the units that finished on their own merits - the rows every success rate, cost per
-- episode, tree and failure-mode table counts (capped, gave-up and not-started units are in the
-- coverage table instead).
CREATE VIEW outcomes AS
SELECT * FROM terminal WHERE state = 'finished';

-- calls: llm_calls with the episode's labels.
--   latest_attempt  TRUE/FALSE for the call's attempt; NULL when the attempt has no episode row
--                   (an attempt lost with its worker).
--   episode_success the success of the call's attempt (NULL without an episode row).
--   model_label     the model's name in the sweep, labelled like attempts.model_label: the call's
--                   model_name (its label, else its model string), else its episode's model, else
--                   (a call outside a sweep) its provider model string. Never the provider string
--                   when a name is known: two labels on one model string stay two models, named
--                   as in every other view.
CREATE VIEW calls AS
SELECT c.*,
  a.unit_id, a.method, a.arm, a.env_split, a.task,
  a.is_latest AS latest_attempt,
  a.success AS episode_success,
  model_label(coalesce(nullif(c.model_name, ''), nullif(a.model, ''), nullif(c.model, '')),
    c.test_double OR coalesce(a.test_double, false)) AS model_label,
  len(c.window_seqs) AS window_len,
  c.prompt_tokens + c.completion_tokens AS total_tokens
FROM llm_calls c
LEFT JOIN attempts a ON a.run_id = c.run_id AND a.episode_id = c.episode_id;

-- nodes: tree_nodes with the child count and the latest version's think and subtasks.
CREATE VIEW nodes AS
WITH kids AS (
  SELECT run_id, episode_id, parent_id, count(*) AS n_children
  FROM tree_nodes WHERE parent_id IS NOT NULL
  GROUP BY run_id, episode_id, parent_id
)
SELECT n.*,
  coalesce(k.n_children, 0) AS n_children,
  k.n_children IS NULL AS is_leaf,
  len(n.versions) AS n_versions,
  n.versions[-1].think AS think,
  n.versions[-1].subtasks AS subtasks
FROM tree_nodes n
LEFT JOIN kids k ON k.run_id = n.run_id AND k.episode_id = n.episode_id AND k.parent_id = n.node_id;

-- tree_stats: one row per episode with a task tree.
--   max_depth         deepest node, in edges from the root (the root has depth 0; episodes.max_depth)
--   levels            max_depth + 1: levels of the tree counting the root as level 1, the
--                     convention of the level_N ablations (level_2 = root and one level below)
--   branching_factor  mean number of children over the nodes that have children (non-leaf nodes);
--                     a node's children are all subtasks it pushed, over all its refinements
--   leaf_failures     nodes with status 'failed' (a one-item reply that is not a valid action,
--                     or an action the environment rejected)
--   refinements       versions beyond each node's first
CREATE VIEW tree_stats AS
SELECT run_id, episode_id,
  count(*) AS nodes,
  max(depth) AS max_depth,
  max(depth) + 1 AS levels,
  count(*) FILTER (WHERE NOT is_leaf) AS internal_nodes,
  avg(n_children) FILTER (WHERE NOT is_leaf) AS branching_factor,
  max(n_children) AS max_children,
  count(*) FILTER (WHERE status = 'failed') AS leaf_failures,
  count(*) FILTER (WHERE kind = 'primitive') AS primitive_nodes,
  sum(greatest(n_versions - 1, 0)) AS refinements
FROM nodes
GROUP BY run_id, episode_id;

-- step_patterns: one row per episode with steps; the loop detectors of the failure taxonomy.
--   longest_invalid_run  longest stretch of consecutive invalid attempts (by step index)
--   max_same_invalid     most attempts of one and the same invalid action string
--   invalid_loop         longest_invalid_run >= 3 OR max_same_invalid >= 3
--   repeated_loop        a cycle of L = 1, 2 or 3 attempts with the same (action, observation,
--                        validity) occurs back to back at least 3 times and over at least 4
--                        attempts: L=1 four identical attempts in a row, L=2 a-b-a-b-a-b, L=3
--                        a-b-c-a-b-c-a-b-c. Repeats that change the observation (progress, e.g.
--                        cutting 1/3, 2/3, 3/3) are not loops.
--   loop_cycle_len       the shortest such L
-- One window pass: h is a hash of (action, observation, valid); lag k looks k attempts back.
CREATE VIEW step_patterns AS
WITH marked AS MATERIALIZED (
  SELECT run_id, episode_id, valid, action,
    sum(CASE WHEN valid THEN 1 ELSE 0 END) OVER w AS valid_so_far,
    h = lag(h, 1) OVER w AND h = lag(h, 2) OVER w AND h = lag(h, 3) OVER w AS loop1,
    h = lag(h, 2) OVER w AND h = lag(h, 4) OVER w
      AND lag(h, 1) OVER w = lag(h, 3) OVER w AND lag(h, 3) OVER w = lag(h, 5) OVER w AS loop2,
    h = lag(h, 3) OVER w AND h = lag(h, 6) OVER w
      AND lag(h, 1) OVER w = lag(h, 4) OVER w AND lag(h, 4) OVER w = lag(h, 7) OVER w
      AND lag(h, 2) OVER w = lag(h, 5) OVER w AND lag(h, 5) OVER w = lag(h, 8) OVER w AS loop3
  FROM (SELECT run_id, episode_id, "index", valid, action, hash(action, observation, valid) AS h FROM steps)
  WINDOW w AS (PARTITION BY run_id, episode_id ORDER BY "index")
), invalid_runs AS (
  SELECT run_id, episode_id, max(n) AS longest_invalid_run
  FROM (SELECT run_id, episode_id, valid_so_far, count(*) AS n FROM marked WHERE NOT valid GROUP BY ALL)
  GROUP BY ALL
), invalid_same AS (
  SELECT run_id, episode_id, max(n) AS max_same_invalid
  FROM (SELECT run_id, episode_id, action, count(*) AS n FROM marked WHERE NOT valid GROUP BY ALL)
  GROUP BY ALL
), per_episode AS (
  SELECT run_id, episode_id,
    count(*) AS attempts,
    count(*) FILTER (WHERE NOT valid) AS invalid_steps,
    CASE WHEN bool_or(loop1) THEN 1 WHEN bool_or(loop2) THEN 2 WHEN bool_or(loop3) THEN 3 END AS loop_cycle_len
  FROM marked
  GROUP BY run_id, episode_id
)
SELECT c.run_id, c.episode_id, c.attempts, c.invalid_steps,
  coalesce(r.longest_invalid_run, 0) AS longest_invalid_run,
  coalesce(q.max_same_invalid, 0) AS max_same_invalid,
  coalesce(r.longest_invalid_run, 0) >= 3 OR coalesce(q.max_same_invalid, 0) >= 3 AS invalid_loop,
  c.loop_cycle_len IS NOT NULL AS repeated_loop,
  c.loop_cycle_len
FROM per_episode c
LEFT JOIN invalid_runs r ON r.run_id = c.run_id AND r.episode_id = c.episode_id
LEFT JOIN invalid_same q ON q.run_id = c.run_id AND q.episode_id = c.episode_id;

-- tool_stats: one row per episode with tool calls (tool_calls rows: a model's tool calls, or the
-- shell commands of a text-action coding agent; schema version 5). A run written before version
-- 5 has no tool_calls rows, so none of its episodes is here.
--   tool_calls       calls recorded (valid or not)
--   invalid_calls    calls that never ran as asked (arguments not JSON, an unknown tool, a call
--                    the tool refused: valid = false)
--   timed_out        calls killed at their time limit
--   nonzero_exits    calls whose process exited with a code other than 0
--   tools            distinct tool names called
--   duration_s       time spent running the calls, summed
--   output_bytes     output the calls produced (before the cap shown to the model), summed
CREATE VIEW tool_stats AS
SELECT run_id, episode_id,
  count(*) AS tool_calls,
  count(*) FILTER (WHERE NOT valid) AS invalid_calls,
  count(*) FILTER (WHERE timed_out) AS timed_out,
  count(*) FILTER (WHERE exit_code <> 0) AS nonzero_exits,
  count(DISTINCT name) AS tools,
  sum(duration_s) AS duration_s,
  CAST(sum(output_bytes) AS BIGINT) AS output_bytes
FROM tool_calls
GROUP BY run_id, episode_id;

-- episode_modes: every unit's row (terminal, any state) with one failure mode, first match wins:
--   success                     end_reason success, or autosubmitted with success (the diff handed in at a limit resolved)
--   infra_error:<kind>          an infrastructure failure (infra_kind: auth, worker_lost ...)
--   model_error:<kind>          end_reason llm_error; kind = error_kind of the episode's last failed call
--   <evaluation reason>         a coding episode that submitted and was judged not resolved (end_reason
--                               agent_done): its evaluations row's reason - tests_failed, patch_failed,
--                               patch_refused (it wrote outside the repository), no_patch (an empty
--                               diff), timeout (the tests ran past the evaluation's limit) - before the
--                               loop detectors: what failed is the verdict, not how the agent got there
--   autosubmitted:<reason>      a limit ended it and the diff handed in there was judged not resolved
--                               (the evaluation's reason; error: the limit); plain autosubmitted
--                               where no evaluations row says why
--   json_failures | truncated | budget_exhausted | episode_limit | env_error    those end reasons
--                               (truncated: a reply cut at the output cap, never counted as a JSON failure)
--   invalid_action_loop         step_cap / call_cap / agent_done with invalid_loop
--   repeated_action_loop        step_cap / call_cap / agent_done with repeated_loop
--   agent_done_early            agent_done without an evaluation (the agent declared the task finished; it was not)
--   step_cap | call_cap         those end reasons
--   other:<end_reason>          anything else
CREATE VIEW episode_modes AS
WITH last_error AS (
  SELECT run_id, episode_id, arg_max(error_kind, call_index) AS last_error_kind
  FROM llm_calls WHERE status = 'error'
  GROUP BY run_id, episode_id
), verdict AS (
  -- one row per judged episode (the evaluations table's rule), kept to one here whatever it holds
  SELECT run_id, episode_id, min(reason) FILTER (WHERE NOT resolved) AS failed_reason
  FROM evaluations
  GROUP BY run_id, episode_id
)
SELECT t.run_id, t.episode_id, t.unit_id, t.model_label, t.arm, t.method, t.label, t.ablation, t.env_split,
  t.task, t.instance_id, t.sampling_seed, t.end_reason, t.success, t.steps, t.llm_calls, t.cost_usd, t.error, t.state,
  coalesce(p.invalid_loop, false) AS invalid_loop,
  coalesce(p.repeated_loop, false) AS repeated_loop,
  coalesce(p.longest_invalid_run, 0) AS longest_invalid_run,
  coalesce(p.max_same_invalid, 0) AS max_same_invalid,
  p.loop_cycle_len,
  le.last_error_kind,
  CASE
    WHEN t.end_reason = 'success' OR (t.end_reason = 'autosubmitted' AND t.success) THEN 'success'
    WHEN t.infra_kind IS NOT NULL THEN 'infra_error:' || t.infra_kind
    WHEN t.end_reason = 'llm_error' THEN 'model_error:' || coalesce(le.last_error_kind, 'unknown')
    WHEN t.end_reason = 'agent_done' AND v.failed_reason IS NOT NULL THEN v.failed_reason
    WHEN t.end_reason = 'autosubmitted' AND v.failed_reason IS NOT NULL THEN 'autosubmitted:' || v.failed_reason
    WHEN t.end_reason IN ('json_failures', 'truncated', 'budget_exhausted', 'episode_limit', 'env_error', 'wiki_error', 'autosubmitted') THEN t.end_reason
    WHEN t.end_reason IN ('step_cap', 'call_cap', 'agent_done') AND coalesce(p.invalid_loop, false) THEN 'invalid_action_loop'
    WHEN t.end_reason IN ('step_cap', 'call_cap', 'agent_done') AND coalesce(p.repeated_loop, false) THEN 'repeated_action_loop'
    WHEN t.end_reason = 'agent_done' THEN 'agent_done_early'
    WHEN t.end_reason IN ('step_cap', 'call_cap') THEN t.end_reason
    ELSE 'other:' || t.end_reason
  END AS mode
FROM terminal t
LEFT JOIN step_patterns p ON p.run_id = t.run_id AND p.episode_id = t.episode_id
LEFT JOIN last_error le ON le.run_id = t.run_id AND le.episode_id = t.episode_id
LEFT JOIN verdict v ON v.run_id = t.run_id AND v.episode_id = t.episode_id;

-- failures: the finished units that did not succeed.
CREATE VIEW failures AS
SELECT * FROM episode_modes WHERE mode <> 'success' AND state = 'finished';

-- fever_samples: the claims of the release's two FEVER samples (main.py's seed 42, the ReAct/Act
-- notebooks' seed 233), one row per claim and sample. Filled by the report builder
-- (reports.sections.fever_samples) from the claims file; empty in a plain `recap sql` session.
CREATE TABLE fever_samples (instance_id VARCHAR, sample_seed BIGINT);

-- paper_scoped: the outcomes rows the paper section counts, once per scope: 'all', and again as
-- 'sync_2_4_6' for Robotouille synchronous tasks 2, 4 and 6 (the cross-model table's tasks), and
-- as 'fever_seed42' / 'fever_seed233' for the FEVER claims of each release sample;
-- arm_label is the arm (its label, else the method), variant the ablation.
CREATE VIEW paper_scoped AS
WITH counted AS (
  SELECT *, coalesce(nullif(arm, ''), method) AS arm_label, ablation AS variant FROM outcomes
)
SELECT *, 'all' AS scope FROM counted
UNION ALL
SELECT *, 'sync_2_4_6' FROM counted
WHERE benchmark = 'robotouille' AND split = 'synchronous' AND split_part(task, '_', 1) IN ('2', '4', '6')
UNION ALL
SELECT c.*, 'fever_seed' || s.sample_seed FROM counted c JOIN fever_samples s USING (instance_id)
WHERE c.benchmark = 'fever';

-- planned_units: the units each run folder's plan.json lists (run_id from its run.json), with
-- whether its model is a test double (from the folder's spec.yaml; NULL when unknown). Filled by
-- the report builder (reports.sections.load_plans); empty in a plain `recap sql` session, where
-- the coverage query falls back to the units that have episode rows.
-- label is the arm's label (plan.json's "method"), method the method's name ("method_name";
-- NULL in a plan written before schema version 2).
CREATE TABLE planned_units (run_dir VARCHAR, run_id VARCHAR, unit_id VARCHAR, label VARCHAR, method VARCHAR,
  model VARCHAR, instance_id VARCHAR, sampling_seed BIGINT, test_double BOOLEAN);
