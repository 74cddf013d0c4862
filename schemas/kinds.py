"""The closed vocabularies of the tables: end reasons, error kinds, statuses, event kinds.

Why one module: each of these strings is written by one layer (the agent, the gateway, the
driver) and read back by another (resume, reports, SQL). As ``Literal`` types the type checker
catches a misspelt kind at the writer, and the runtime tuples (``END_REASONS``, ...) are derived
from the same definition, so a kind cannot be added in one place and forgotten in the other.
Pure definitions, no I/O.
"""

from __future__ import annotations

from typing import Literal, get_args

#: why an episode ended (``episodes.end_reason``); ``infra_error`` is written by the driver only.
#: ``wiki_error``: a Wikipedia answer (FEVER) could not be had or read; it is an environment
#: error with its own reason because one kind of it (``unavailable``: the site refused or timed
#: out after the retries) is infrastructure that ``recap resume`` retries (schemas.labels).
#: ``autosubmitted``: a limit ended the episode (cost cap, token/call/step/time limit, context
#: overflow, repeated unusable replies) while the repository held a non-empty diff, and that diff
#: was handed in and graded (SWE-agent's autosubmission, swebench-recap/sweagent/agent/agents.py:
#: 888-933, 1250-1315): ``success`` is the verdict, ``error`` names the limit first
#: (``episode_limit: $10.01 spent (limit $10)``)
EndReason = Literal[
    "success",
    "step_cap",
    "call_cap",
    "agent_done",
    "json_failures",
    "llm_error",
    "budget_exhausted",
    "episode_limit",
    "env_error",
    "truncated",
    "wiki_error",
    "autosubmitted",
]
END_REASONS: tuple[str, ...] = get_args(EndReason)

#: the end reason of a row whose unit failed on infrastructure (the model service, a worker)
InfraEndReason = Literal["infra_error"]
#: every value ``episodes.end_reason`` can hold
RowEndReason = Literal[EndReason, InfraEndReason]

#: the classes a failed model call is sorted into (``llm_calls.error_kind``, ``LLMError.kind``)
#: ``invalid_reply``: the provider answered HTTP 200 with the model's reply, which no JSON reader
#: can read (nested deeper than Python's recursion limit): the model's failure, not infrastructure
LLMErrorKind = Literal[
    "rate_limit",
    "timeout",
    "server_error",
    "context_length",
    "bad_request",
    "auth",
    "budget",
    "invalid_reply",
]
LLM_ERROR_KINDS: tuple[str, ...] = get_args(LLMErrorKind)

#: ``llm_calls.status``
CallStatus = Literal["ok", "error"]

#: ``tree_nodes.status``: a subtask not yet finished, finished, or given up
NodeStatus = Literal["open", "done", "failed"]
#: ``tree_nodes.kind``: the root task, a subtask that is decomposed further, an environment
#: action, or (ADaPT) a task handed to the executor
NodeKind = Literal["root", "composite", "primitive", "executor_task"]

#: ``events.severity``
Severity = Literal["info", "warning", "error"]
#: ``events.source``: who wrote the row
EventSource = Literal["driver", "gateway"]
#: ``events.kind``: what happened
EventKind = Literal[
    # the driver's session
    "run_started",
    "run_resumed",
    "workers_started",
    "run_finished",
    "run_stopped",
    "interrupted",
    "worker_restarted",
    "worker_lost",
    "attempt_failed",
    "unit_failed",
    "unit_abandoned",
    "run_cap_reached",
    "model_cap_reached",
    "model_stopped",
    "sink_lost",
    "sink_log_recovered",
    "leftovers_removed",
    # the models the sweep serves itself (pipeline.serving)
    "serve_started",
    "serve_stopped",
    "serve_cost",
    "serve_leftover_removed",
    # the gateway and its budget ledger
    "retry",
    "call_failed",
    "usage_rejected",
    "orphans_charged",
    "concurrency_limit",
    "ledger_restored",
]
EVENT_KINDS: tuple[str, ...] = get_args(EventKind)
