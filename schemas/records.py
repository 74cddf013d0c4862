"""Record types: one dataclass per table row.

The agent (``recap/``) emits messages, calls, tree nodes and steps; the pipeline adds episode,
event and run rows. Records carry ``episode_id`` but not ``run_id``: the sink stamps the run id
when it writes, so the method stays unaware of where its records go.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

from schemas.kinds import CallStatus, EventKind, EventSource, LLMErrorKind, NodeKind, NodeStatus, RowEndReason, Severity

#: 2: episodes gained ``label``, ``profile``, ``ablation`` and ``provider_model`` (``method`` holds
#: the method's name, no longer the arm's label), ALFWorld rows are one benchmark split
#: (``valid_unseen``, task = task type) and infrastructure failures end ``infra_error``; parts
#: written under version 1 are mapped on read (:mod:`schemas.versions`).
#: 3: ``llm_calls`` gained ``model_name``, the model's name in the sweep (what ``episodes.model``
#: holds) beside ``model``, the provider model string; parts written under version 2 get it
#: derived from their ``deployment`` on read.
#: 4: ``episodes.seed`` renamed ``sampling_seed`` (the unit's sampling seed, apart from an
#: instance's layout seed and a test double's noise seed); parts written under version 3 or
#: earlier have their ``seed`` column read as ``sampling_seed``
#: 5: tool calls (issue 28): ``messages`` gained ``tool_call_id`` and ``tool_calls`` (null in parts
#: of version 4 or earlier: those runs had no tool calls), and the new ``tool_calls`` table holds
#: one row per call a model made (a run without that table has none); the ``evaluations`` table
#: (issue 29: one row per judged SWE-bench submission) was added under the same version, since a
#: new table changes no part of an existing one (a run without it has no rows there)
SCHEMA_VERSION = 5


@dataclass(frozen=True)
class MessageRecord:
    """One message of the shared LLM history, written once when it is inserted.

    ``seq`` numbers the messages of an episode from 0 in insertion order; call records refer to
    messages by these numbers (the window of a call), never by copying their text.
    ``kind`` says which prompt template produced it (``demonstration``, ``task``, ``descend``,
    ``leaf_done``, ``leaf_judge``, ``leaf_fail``, ``nonleaf_done``, ``nonleaf_judge``,
    ``depth_cap``, ``repair``, ``reply``, ``observation``, ``feedback``, ...).
    """

    table: ClassVar[str] = "messages"
    episode_id: str
    seq: int
    role: str
    kind: str
    content: str
    node_id: int | None = None
    pinned: bool = False
    #: a ``tool`` message: the id of the tool call it answers
    tool_call_id: str | None = None
    #: an assistant message that calls tools: the calls as JSON, ``[{"id", "name", "arguments"}]``
    #: in the model's order (``arguments`` the raw string the model wrote)
    tool_calls: str | None = None


@dataclass(frozen=True)
class CallRecord:
    """One LLM call: the window it saw (by message seq), its accounting and its outcome.

    ``model`` is the provider model string the call was sent as; ``model_name`` the model's
    unique name in the sweep (its label, else its model string: ``episodes.model``), which
    spend and caps are kept by. Two sweep entries may share a model string, never a name."""

    table: ClassVar[str] = "llm_calls"
    episode_id: str
    call_index: int
    call_key: str
    purpose: str
    window_seqs: tuple[int, ...]
    model: str
    status: CallStatus
    node_id: int | None = None
    response_seq: int | None = None
    error_kind: LLMErrorKind | None = None
    error_message: str | None = None
    prompt_tokens: int = 0
    cached_prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    latency_s: float = 0.0
    retries: int = 0
    token_count_source: str = "provider"  # provider | tokenizer | estimate
    served_from: str = "provider"  # provider | cache | ledger | replay
    deployment: str | None = None
    test_double: bool = False
    #: the provider's finish reason ("stop", "length", ...) when known
    finish_reason: str | None = None
    #: litellm's own cost estimate, kept only as a cross-check of ``cost_usd`` (our price table)
    provider_cost_usd: float | None = None
    #: prompt tokens written to the provider's prompt cache (billed at the model's cache_write
    #: price; Anthropic-style caching only, else 0); like ``cached_prompt_tokens``, a part of
    #: ``prompt_tokens``
    cache_write_tokens: int = 0
    #: the model's name in the sweep (null: a call made outside a sweep, by an unnamed deployment)
    model_name: str | None = None


@dataclass(frozen=True)
class NodeVersion:
    """One (think, subtasks) version of a tree node; ``call_index`` is None for a shortcut."""

    version: int
    think: str | None
    subtasks: tuple[str, ...]
    call_index: int | None = None
    message_seq: int | None = None


@dataclass(frozen=True)
class NodeRecord:
    """A node of the ReCAP context tree with every version it had.

    ``kind`` is ``root``, ``composite`` or ``primitive``; ``status`` is ``done`` (completed),
    ``failed`` (leaf failure: not a valid action) or ``open`` (the episode ended inside it).
    ``child_index`` is the node's position among its parent's children in creation order.
    """

    table: ClassVar[str] = "tree_nodes"
    episode_id: str
    node_id: int
    parent_id: int | None
    depth: int
    child_index: int
    task: str
    kind: NodeKind
    status: NodeStatus
    versions: tuple[NodeVersion, ...] = ()
    step_index: int | None = None


@dataclass(frozen=True)
class StepRecord:
    """One attempted environment action.

    ``index`` counts attempts; ``env_step`` is the environment's step count after the attempt
    (an action rejected before reaching the environment has ``valid`` False and takes no step).
    """

    table: ClassVar[str] = "steps"
    episode_id: str
    index: int
    env_step: int
    action: str
    valid: bool
    observation: str
    done: bool
    success: bool
    node_id: int | None = None


@dataclass(frozen=True)
class ToolCallRecord:
    """One tool call a model made (or one shell command of a text-action coding agent), with what
    running it cost: the ``tool_calls`` table.

    ``index`` numbers an episode's calls from 0; ``step_index`` is the ``steps`` row of the same
    attempt; ``message_seq`` the assistant message that carried the call (None for a command
    written as text). ``valid`` False: the call never ran as asked (arguments that are not JSON,
    an unknown tool, a call the tool refused), ``error`` says why. ``exit_code`` is None when no
    process ran or it was killed (``timed_out``); ``output_bytes`` is the output's size before the
    cap shown to the model. Every call a reply made has its row, run or not (a call of a reply that
    was repaired: ``error`` says it was not run). Model-written fields are bounded
    (:mod:`recap.row_bounds`): ``arguments`` at 65,536 characters, ``name`` and ``call_id`` at 256,
    a longer one cut with `` [cut: N characters in all]`` after the part kept.
    """

    table: ClassVar[str] = "tool_calls"
    episode_id: str
    index: int
    step_index: int
    name: str
    arguments: str
    valid: bool
    call_id: str | None = None
    message_seq: int | None = None
    node_id: int | None = None
    error: str | None = None
    exit_code: int | None = None
    duration_s: float = 0.0
    output_bytes: int = 0
    timed_out: bool = False


@dataclass(frozen=True)
class EpisodeRecord:
    """The terminal row of one attempt at one unit of work.

    Identity of the arm: ``method`` is the method's name (``recap``, ``react``, ``act``, ``cot``,
    ``standard``, ``adapt``); ``label`` the arm's label from the sweep (``recap-no-think``,
    ``recap[paper,level_3]``); ``profile`` the settings profile (``paper``, ``released``) or
    None; ``ablation`` None for the original method, else the ablation's name
    (:func:`pipeline.units.resolve_ablation`: ``no_think``, ``level_3`` ...). ``model`` is the
    model's label in the sweep, ``provider_model`` the model string sent to the provider
    (``openai/gpt-4o-2024-08-06``, ``offline/expert``).

    Where: ``benchmark``/``split``/``task`` - Robotouille ``synchronous``/``asynchronous`` and
    the environment's name; ALFWorld one split ``valid_unseen`` (its 134 unseen games) and the
    task type (``put``, ``clean``, ``heat``, ``cool``, ``examine``, ``puttwo``). The instance
    id's ``@N`` is the instance's layout seed; ``sampling_seed`` is the unit's own (the sweep's
    ``sampling_seeds``: repetitions of one instance).

    ``end_reason`` ``infra_error``: the model service or the worker failed (not an outcome of
    the agent); ``error`` then starts with the failure's kind (``auth: ...``) or says that the
    driver gave up (``gave up after N failed attempts (infrastructure: worker_lost); ...``).
    """

    table: ClassVar[str] = "episodes"
    episode_id: str
    unit_id: str
    attempt: int
    benchmark: str
    split: str
    task: str
    instance_id: str
    sampling_seed: int
    method: str
    method_config: str  # canonical JSON of the agent settings
    model: str
    end_reason: RowEndReason
    success: bool
    steps: int
    llm_calls: int
    prompt_tokens: int
    cached_prompt_tokens: int
    completion_tokens: int
    cost_usd: float
    wall_s: float
    step_cap: int
    step_multiplier: float
    optimal_steps: int | None = None
    max_depth: int = 0
    error: str | None = None
    worker_id: str | None = None
    started_at: float = 0.0
    ended_at: float = 0.0
    test_double: bool = False
    label: str = ""
    profile: str | None = None
    ablation: str | None = None
    provider_model: str | None = None


@dataclass(frozen=True)
class EventRecord:
    """Something that happened outside an agent's messages: retries, errors, restarts, caps."""

    table: ClassVar[str] = "events"
    ts: float
    source: EventSource
    kind: EventKind
    severity: Severity = "info"
    episode_id: str | None = None
    unit_id: str | None = None
    detail: str = "{}"  # JSON


@dataclass(frozen=True)
class RunRecord:
    """One row per run start or resume: the spec, versions, revision and host."""

    table: ClassVar[str] = "run"
    started_at: float
    spec_yaml: str
    spec_hash: str
    package_versions: str  # JSON
    git_revision: str | None
    host: str
    command: str
    schema_version: int = SCHEMA_VERSION


@dataclass(frozen=True)
class WikiPageRecord:
    """One distinct Wikipedia answer body a FEVER run read, stored once by its content address.

    Why content-addressed: the same page is read by many episodes (every method searches the
    same claim's entities), so the body is kept once per ``sha256`` and each request points at
    it (:class:`WikiRequestRecord`). A worker writes a body once; two workers that read the
    same page may each write it, and such rows are the same bytes: the ``wiki_pages`` view of a
    run folder holds one row per ``(run_id, sha256)`` (``unique_by``), the rows as written stay
    readable as ``wiki_pages_raw`` (reports/views.py)."""

    table: ClassVar[str] = "wiki_pages"
    #: the columns that name one row: the query view keeps one row for each
    unique_by: ClassVar[tuple[str, ...]] = ("run_id", "sha256")
    sha256: str
    body: bytes
    size: int


@dataclass(frozen=True)
class WikiRequestRecord:
    """One Wikipedia request an episode answered live: the request URL (the snapshot key), the
    ``sha256`` of the body it got (``wiki_pages``), the HTTP status, when (ISO 8601 UTC), where
    redirects led and the text encoding the body was decoded with."""

    table: ClassVar[str] = "wiki_requests"
    episode_id: str
    url: str
    sha256: str
    status: int
    fetched_at: str
    final_url: str
    encoding: str


@dataclass(frozen=True)
class EvaluationRecord:
    """How one SWE-bench submission was judged: the ``evaluations`` table, one row per judged
    episode (workers/envs/swe/evaluate.py, grading.py).

    ``resolved``/``reason`` are the verdict the episode's ``success`` is (``graded_by``: the
    official harness's grade when it ran, else ours); ``ours_resolved`` is our evaluator's own
    verdict and ``official_resolved``/``official_status`` the harness's (``RESOLVED_FULL``,
    ``RESOLVED_PARTIAL``, ``RESOLVED_NO``; null status where the harness writes no report: no
    patch, a patch that does not apply, a timeout; both null when the official grading did not
    run, ``grading`` ``ours`` or no ``swebench`` package). ``reason``: ``resolved``, ``no_patch``,
    ``patch_failed``, ``patch_refused`` (it wrote outside the repository: never applied),
    ``tests_failed``, ``timeout``. ``tests`` is JSON, each FAIL_TO_PASS and
    PASS_TO_PASS test id -> its status as the deciding grader read the log (``MISSING``: not
    reported); the counts are that grader's. ``patch`` is the submitted diff (``patch_bytes`` its
    UTF-8 size); ``log`` the evaluation's log, its last :data:`EVALUATION_LOG_CAP` bytes when longer
    (``log_bytes`` the whole log's size); ``duration_s`` the evaluation's wall time."""

    table: ClassVar[str] = "evaluations"
    episode_id: str
    instance_id: str
    resolved: bool
    reason: str
    graded_by: str
    grading: str
    ours_resolved: bool
    tests: str
    fail_to_pass_passed: int
    fail_to_pass_total: int
    pass_to_pass_passed: int
    pass_to_pass_total: int
    patch: str
    patch_bytes: int
    log: str
    log_bytes: int
    duration_s: float
    official_resolved: bool | None = None
    official_status: str | None = None
    official_parser: str | None = None


#: bytes of an evaluation's log an ``evaluations`` row keeps (the tail: pytest's summary is last)
EVALUATION_LOG_CAP = 200_000


Record = (
    MessageRecord
    | CallRecord
    | NodeRecord
    | StepRecord
    | ToolCallRecord
    | EpisodeRecord
    | EventRecord
    | RunRecord
    | WikiPageRecord
    | WikiRequestRecord
    | EvaluationRecord
)

ALL_RECORD_TYPES: tuple[type, ...] = (
    MessageRecord,
    CallRecord,
    NodeRecord,
    StepRecord,
    EpisodeRecord,
    EventRecord,
    RunRecord,
    WikiPageRecord,
    WikiRequestRecord,
    ToolCallRecord,
    EvaluationRecord,
)

# keeps `field` importable for callers building records generically
_ = field
