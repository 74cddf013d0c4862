"""What every agent shares at run time: the conversation with the model, the environment driver,
episode ends and results.

* :class:`Conversation` owns the shared history, builds each request from the current window,
  repairs malformed JSON with a bounded re-ask, recovers from context-length errors by dropping
  the oldest unpinned messages, enforces the per-episode call/token/cost caps and emits one
  :class:`~schemas.records.CallRecord` per call.
* :class:`EnvDriver` wraps the environment: exact action lookup, step records, the step cap and
  the end of the episode.
* Any way an episode ends raises :class:`EpisodeEnd` with a named reason; the agent turns it into
  an :class:`EpisodeResult`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from recap.config import AgentConfig
from recap.env import EnvError, Environment, InvalidActionError, Reset, Step, agent_action
from recap.history import History
from recap.jsonreply import ReplyFormatError, parse_json_object
from recap.llm import LLMClient, LLMError, LLMRequest, LLMResponse, ToolCall, ToolDef
from recap.row_bounds import MAX_ARGUMENTS_CHARS, MAX_NAME_CHARS, cut
from schemas import kinds
from schemas.kinds import EndReason, LLMErrorKind
from schemas.outcomes import BudgetRefusal, EpisodeResult
from schemas.records import CallRecord, Record, StepRecord, ToolCallRecord

#: why an episode can end (:data:`schemas.kinds.EndReason`)
END_REASONS = kinds.END_REASONS

Emit = Callable[[Record], None]

#: the result given to a tool call of a reply that had to be repaired (the call was not run)
NOT_RUN = "not run: the reply that made this call could not be used"


@dataclass(frozen=True)
class ToolUse:
    """The tools one request offers and its tool-choice setting (none: a plain chat request),
    and the stop sequences it is sent with (none: the provider's default; the released FEVER
    notebooks stop each call at ``"\nObservation i:"``, React.ipynb cell 4).
    ``one_call``: a reply may make at most one tool call; one that makes more is re-asked with
    the text this gives for its number of calls (SWE-agent's function-calling parser,
    swebench-recap/sweagent/tools/parsing.py:439-449)."""

    tools: tuple[ToolDef, ...] = ()
    choice: str | None = None
    one_call: Callable[[int], str] | None = None
    #: the reply text's JSON schema (:attr:`recap.llm.LLMRequest.response_schema`)
    schema: Mapping[str, Any] | None = None
    stop: tuple[str, ...] = ()


class EpisodeEnd(Exception):
    """Raised from anywhere inside an episode to end it with a named reason."""

    def __init__(
        self,
        reason: EndReason,
        detail: str = "",
        *,
        error_kind: LLMErrorKind | None = None,
        refusal: BudgetRefusal | None = None,
        resolved: bool = False,
    ):
        if reason not in END_REASONS:
            raise ValueError(f"unknown end reason {reason!r}")
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail
        self.error_kind = error_kind
        #: ``budget_exhausted``: the cap that refused the call
        self.refusal = refusal
        #: ``autosubmitted``: the verdict on the work handed in at the limit
        self.resolved = resolved

    @property
    def success(self) -> bool:
        """Whether the episode reached its goal: ``success``, or work handed in at a limit that
        was judged resolved."""
        return self.reason == "success" or (self.reason == "autosubmitted" and self.resolved)


#: the end reasons that are a limit reached (not a failure of the model service or the
#: environment): the cost, token and call caps (``episode_limit`` also for the gateway's refusal
#: at the per-instance cap, and an environment's own time or output limit), the step cap, and
#: unusable replies past the repair budget (the release's ``exit_format``, agents.py:1308-1315).
#: A context overflow (``llm_error`` of kind ``context_length``) is one too (:func:`is_limit`)
LIMIT_END_REASONS: frozenset[str] = frozenset({"episode_limit", "call_cap", "step_cap", "json_failures"})


def is_limit(end: EpisodeEnd) -> bool:
    """Whether ``end`` is a limit reached, after which the work so far is handed in and graded
    (SWE-agent's ``exit_cost``, ``exit_context``, ``exit_total_execution_time``, ``exit_format``
    autosubmissions, swebench-recap/sweagent/agent/agents.py:1250-1315)."""
    return end.reason in LIMIT_END_REASONS or (end.reason == "llm_error" and end.error_kind == "context_length")


class _TooManyCalls(ReplyFormatError):
    """A reply that made more tool calls than one where one is allowed; ``prompt`` re-asks."""

    def __init__(self, prompt: str, problem: str) -> None:
        super().__init__(problem)
        self.prompt = prompt


def repair_prompt(problem: str, expected: str) -> str:
    """The user message that re-asks after a reply that could not be used: what was wrong with it
    (``problem``) and the JSON form expected."""
    return (
        f"I could not use your last reply: {problem}.\n"
        f"Answer again with a single JSON object of the form {expected} and nothing else."
    )


@dataclass
class Usage:
    """Running totals of one episode's model calls (tokens, USD, JSON repairs), shared by all its
    contexts; the episode's call, token and cost caps are checked against them."""

    calls: int = 0
    prompt_tokens: int = 0
    cached_prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    json_repairs: int = 0


class Conversation:
    """The single shared LLM context of an episode and the only way an agent calls the model."""

    def __init__(
        self,
        *,
        episode_id: str,
        client: LLMClient,
        config: AgentConfig,
        style: str,
        emit: Emit,
        expected_format: str,
        reply_fields: tuple[str, ...] = (),
        usage: Usage | None = None,
        history: History | None = None,
    ) -> None:
        self.episode_id = episode_id
        self.client = client
        self.config = config
        self.style = style
        self.emit = emit
        self.expected_format = expected_format
        #: the reply's fields (``Agent.reply_fields``), told to offline test doubles in the hints
        self.reply_fields = tuple(reply_fields)
        self.history = (
            history
            if history is not None
            else History(
                episode_id,
                config.history_window(),
                mode=config.window_mode,
                block=config.window_block,
                emit=emit,
                counts_pins=config.history_counts_pins(),
                keep=config.history_keep(),
            )
        )
        self.usage = usage if usage is not None else Usage()
        #: records a tool call that was never run (its reply was repaired): the episode's
        #: :meth:`EnvDriver.record_not_run`, set by :class:`Episode`
        self.record_not_run: Callable[[ToolCall, int | None, int], None] | None = None

    def fork(
        self, *, expected_format: str | None = None, style: str | None = None, reply_fields: tuple[str, ...] | None = None
    ) -> Conversation:
        """A separate, empty context for the same episode (ADaPT's isolated planner/executor
        prompts): usage, caps and message numbering are shared, the history is not."""
        cfg = self.config
        return Conversation(
            episode_id=self.episode_id,
            client=self.client,
            config=cfg,
            style=style or self.style,
            emit=self.emit,
            expected_format=expected_format or self.expected_format,
            reply_fields=self.reply_fields if reply_fields is None else reply_fields,
            usage=self.usage,
            history=History(
                self.episode_id,
                cfg.history_window(),
                mode=cfg.window_mode,
                block=cfg.window_block,
                emit=self.emit,
                counter=self.history.counter,
                counts_pins=cfg.history_counts_pins(),
                keep=cfg.history_keep(),
            ),
        )

    def pin(self, kind: str, content: str) -> int:
        return self.history.pin("user", kind, content)

    def forget(self, seq: int) -> None:
        """Take the message ``seq`` out of the context (its ``messages`` row stays): a released
        loop that keeps its own record of a step instead of the model's reply (React.ipynb cell 4)."""
        self.history.forget(seq)

    def pin_message(self, role: str, kind: str, content: str) -> int:
        """Pin a message with its own role (the authors' system text and example replies)."""
        return self.history.pin(role, kind, content)

    def ask(
        self,
        prompt: str | None,
        kind: str,
        parse: Callable[[dict[str, Any]], dict[str, Any]],
        *,
        node_id: int | None = None,
        context: Mapping[str, Any] | None = None,
        decode: Callable[[str], dict[str, Any]] = parse_json_object,
        stop: tuple[str, ...] = (),
    ) -> tuple[dict[str, Any], int]:
        """Send ``prompt`` and return (parsed reply, seq of the reply message); ``stop``: the
        stop sequences the request carries.

        ``prompt`` None means the prompt is already in the history (the pinned task prompt).
        A malformed reply is answered with a repair message, at most ``max_json_repairs`` times;
        then the episode ends with ``json_failures``. ``decode`` turns the reply text into the
        object ``parse`` checks (JSON by default; the plain-text formats of
        :mod:`recap.baselines.textreply` pass the text through and handle malformed replies
        themselves, as the released code does).
        """
        if prompt is not None:
            self.history.add("user", kind, prompt, node_id)
        parsed, _calls, seq = self._ask_loop(kind, parse, node_id, context, decode, ToolUse(stop=tuple(stop)))
        return parsed, seq

    def ask_tools(
        self,
        prompt: str | None,
        kind: str,
        parse: Callable[[dict[str, Any]], dict[str, Any]],
        *,
        tools: tuple[ToolDef, ...],
        tool_choice: str | None = None,
        node_id: int | None = None,
        context: Mapping[str, Any] | None = None,
        decode: Callable[[str], dict[str, Any]] = parse_json_object,
        one_call: Callable[[int], str] | None = None,
        schema: Mapping[str, Any] | None = None,
    ) -> tuple[dict[str, Any], tuple[ToolCall, ...], int]:
        """:meth:`ask` with ``tools`` the model may call: (parsed text, tool calls, reply seq).

        A reply that calls tools and writes no text parses as ``{}`` (the caller's ``parse``
        decides what an empty reply means). The caller must answer every returned call with
        :meth:`add_tool_result` before it asks again. A reply whose text cannot be used is
        repaired as in :meth:`ask`; its tool calls are answered first as not run, so the
        history stays a valid tool conversation. With ``one_call`` (the re-ask text for a number
        of calls), a reply making several calls is re-asked the same way, from the same repair
        budget (SWE-agent requeries its format errors from one budget, then exits with the work
        handed in: swebench-recap/sweagent/agent/agents.py:1204,1217-1221,1308-1315). ``schema``:
        the reply text's JSON schema, sent as a strict response format where the provider
        supports it (:attr:`recap.llm.LLMRequest.response_schema`)."""
        if prompt is not None:
            self.history.add("user", kind, prompt, node_id)
        return self._ask_loop(
            kind, parse, node_id, context, decode, ToolUse(tools, tool_choice, one_call=one_call, schema=schema)
        )

    def add_tool_result(self, call: ToolCall, content: str, node_id: int | None = None) -> int:
        """Answer one tool call of the last reply with its result (a ``tool`` message)."""
        return self.history.add("tool", "tool_result", content, node_id, tool_call_id=call.id)

    def _ask_loop(
        self,
        kind: str,
        parse: Callable[[dict[str, Any]], dict[str, Any]],
        node_id: int | None,
        context: Mapping[str, Any] | None,
        decode: Callable[[str], dict[str, Any]],
        tools: ToolUse,
    ) -> tuple[dict[str, Any], tuple[ToolCall, ...], int]:
        """Call until a reply parses, repairing at most ``max_json_repairs`` times."""
        repairs = 0
        purpose = kind
        while True:
            response, seq = self._call(purpose, node_id, context or {}, tools)
            calls = response.tool_calls
            try:
                if tools.one_call is not None and len(calls) > 1:
                    raise _TooManyCalls(tools.one_call(len(calls)), f"the reply made {len(calls)} tool calls")
                obj = {} if calls and not response.text.strip() else decode(response.text)
                return parse(obj), calls, seq
            except ReplyFormatError as exc:
                for call in calls:  # every call the reply made is in tool_calls, run or not
                    if self.record_not_run is not None:
                        self.record_not_run(call, node_id, seq)
                if repairs >= self.config.max_json_repairs:
                    raise EpisodeEnd("json_failures", str(exc)) from None
                repairs += 1
                self.usage.json_repairs += 1
                for call in calls:
                    self.add_tool_result(call, NOT_RUN, node_id)
                text = exc.prompt if isinstance(exc, _TooManyCalls) else repair_prompt(str(exc), self.expected_format)
                self.history.add("user", "repair", text, node_id)
                purpose = "repair"

    # -- one model call, with context-length recovery -------------------------------------------
    def _call(self, purpose: str, node_id: int | None, context: Mapping[str, Any], tools: ToolUse) -> tuple[LLMResponse, int]:
        while True:
            self._check_caps()
            call_index = self.usage.calls
            self.usage.calls += 1
            request = self._request(call_index, purpose, node_id, context, tools)
            started = time.perf_counter()
            try:
                response = self.client.complete(request)
            except LLMError as exc:
                self._record_error(request, exc, time.perf_counter() - started)
                self._end_on_error(exc)
                continue  # the oldest messages were dropped: ask again
            except EnvError as exc:  # the client reads the environment (an offline model's expert plan)
                self.usage.calls -= 1  # nothing was sent
                raise EpisodeEnd(exc.end_reason, exc.row_error()) from exc
            seq = self._record_reply(request, response)
            if response.finish_reason == "length":
                # the reply hit the output cap: whatever it holds is cut off, so it is neither
                # parsed nor repaired (a repair would pay again for the same cut)
                raise EpisodeEnd(
                    "truncated",
                    f"reply cut at the output cap ({response.completion_tokens} tokens, max_tokens {self.config.max_tokens})",
                )
            return response, seq

    def _request(
        self, call_index: int, purpose: str, node_id: int | None, context: Mapping[str, Any], tools: ToolUse
    ) -> LLMRequest:
        """The request for the history as it stands, with the hints offline models read."""
        return LLMRequest(
            messages=self.history.messages(),
            episode_id=self.episode_id,
            call_index=call_index,
            purpose=purpose,
            window_seqs=self.history.seqs(),
            node_id=node_id,
            response_seq=self.history.next_seq,
            temperature=self.config.temperature,
            max_tokens=self.config.max_tokens,
            json_mode=self.config.json_mode and not tools.tools,
            hints={"style": self.style, "purpose": purpose, "reply_fields": self.reply_fields, **context},
            tools=tools.tools,
            tool_choice=tools.choice,
            response_schema=tools.schema,
            stop=tools.stop,
            episode_cap_usd=self.config.max_episode_cost_usd,
            episode_spent_usd=self.usage.cost_usd,
        )

    def _end_on_error(self, exc: LLMError) -> None:
        """End the episode for a failed call; returns only for a context overflow after dropping the
        oldest messages (the call is then made again)."""
        if exc.kind == "context_length":
            if self.config.context_overflow == "end":  # SWE-agent's exit_context (agents.py:1272-1276)
                raise EpisodeEnd(
                    "llm_error", "context length exceeded (the whole history is kept)", error_kind=exc.kind
                ) from None
            if self.history.drop_oldest(self.config.context_drop) == 0:
                raise EpisodeEnd("llm_error", "context length exceeded with nothing left to drop", error_kind=exc.kind) from None
            return
        if exc.kind == "budget" and exc.refusal is not None and exc.refusal.scope == "episode":
            # the episode's own cap refused the call before it was sent: the episode is over, the
            # run and the model go on (not budget_exhausted, which a raised cap would resume)
            raise EpisodeEnd("episode_limit", exc.message, error_kind=exc.kind) from None
        if exc.kind == "budget":
            raise EpisodeEnd("budget_exhausted", exc.message, error_kind=exc.kind, refusal=exc.refusal) from None
        raise EpisodeEnd("llm_error", str(exc), error_kind=exc.kind) from None

    def _record_reply(self, request: LLMRequest, response: LLMResponse) -> int:
        """Add the reply to the history, count its usage and emit its call row; the reply's seq."""
        seq = self.history.add("assistant", "reply", response.text, request.node_id, tool_calls=response.tool_calls)
        u = self.usage
        u.prompt_tokens += response.prompt_tokens
        u.cached_prompt_tokens += response.cached_prompt_tokens
        u.completion_tokens += response.completion_tokens
        u.cost_usd += response.cost_usd
        self.emit(
            CallRecord(
                episode_id=self.episode_id,
                call_index=request.call_index,
                call_key=request.call_key,
                purpose=request.purpose,
                window_seqs=request.window_seqs,
                model=response.model,
                status="ok",
                node_id=request.node_id,
                response_seq=seq,
                prompt_tokens=response.prompt_tokens,
                cached_prompt_tokens=response.cached_prompt_tokens,
                completion_tokens=response.completion_tokens,
                cost_usd=response.cost_usd,
                latency_s=response.latency_s,
                retries=response.retries,
                token_count_source=response.token_count_source,
                served_from=response.served_from,
                deployment=response.deployment,
                test_double=response.test_double,
                finish_reason=response.finish_reason,
                provider_cost_usd=response.provider_cost_usd,
            )
        )
        return seq

    def _check_caps(self) -> None:
        cfg, u = self.config, self.usage
        if cfg.max_llm_calls is not None and u.calls >= cfg.max_llm_calls:
            raise EpisodeEnd("call_cap", f"{u.calls} LLM calls (cap {cfg.max_llm_calls})")
        if cfg.max_episode_tokens is not None and u.prompt_tokens + u.completion_tokens >= cfg.max_episode_tokens:
            raise EpisodeEnd("episode_limit", f"{u.prompt_tokens + u.completion_tokens} tokens (limit {cfg.max_episode_tokens})")
        if cfg.max_episode_cost_usd is not None and u.cost_usd >= cfg.max_episode_cost_usd:
            raise EpisodeEnd("episode_limit", f"${u.cost_usd:.4f} spent (limit ${cfg.max_episode_cost_usd})")

    def _record_error(self, request: LLMRequest, exc: LLMError, latency: float) -> None:
        self.usage.cost_usd += exc.cost_usd
        self.emit(
            CallRecord(
                episode_id=self.episode_id,
                call_index=request.call_index,
                call_key=request.call_key,
                purpose=request.purpose,
                window_seqs=request.window_seqs,
                model="",
                status="error",
                node_id=request.node_id,
                error_kind=exc.kind,
                error_message=exc.message[:500],
                cost_usd=exc.cost_usd,
                latency_s=latency,
                retries=exc.retries,
            )
        )


class EnvDriver:
    """Steps the environment with exact action lookup, records every attempt, ends the episode."""

    def __init__(self, env: Environment, episode_id: str, emit: Emit) -> None:
        self.env = env
        self.episode_id = episode_id
        self.emit = emit
        self.steps = 0
        self.attempts = 0
        self.invalid = 0
        #: tool calls recorded (the ``tool_calls`` rows' index)
        self.tool_calls = 0
        self.observation = ""
        self.goal = ""
        self.valid_actions: tuple[str, ...] | None = None
        self._valid_index: dict[str, int] = {}
        self.success = False

    def reset(self) -> Reset:
        try:
            r = self.env.reset()
        except EnvError as exc:  # the environment's own reason when it has one (FEVER: wiki_error)
            raise EpisodeEnd(exc.end_reason, exc.row_error("reset failed")) from exc
        except Exception as exc:  # engine failure at reset
            raise EpisodeEnd("env_error", f"reset failed: {exc}") from exc
        self.observation, self.goal = r.observation, r.goal
        self._set_valid(r.valid_actions)
        return r

    def _set_valid(self, valid: tuple[str, ...] | None) -> None:
        self.valid_actions = valid
        self._valid_index = {} if valid is None else {a: i for i, a in enumerate(valid)}

    def is_valid(self, action: str) -> bool:
        """Exact membership (index lookup), never substring matching."""
        return self.valid_actions is None or action in self._valid_index

    def reject(self, action: str, node_id: int | None = None) -> None:
        """Record an action that is not valid and never reaches the environment."""
        self.invalid += 1
        self._record(action, False, self.observation, False, node_id)

    def execute(self, action: str, node_id: int | None = None) -> Step:
        """Run ``action`` as the agent-facing layer spells it for this environment
        (:func:`recap.env.agent_action`; that spelling is what is recorded). Invalid actions
        reach the environment only in ``step`` mode."""
        action = agent_action(self.env, action)
        valid = self.is_valid(action)
        if not valid and self.env.invalid_action_mode == "reject":
            self.reject(action, node_id)
            raise InvalidActionError(action)
        if not valid:
            self.invalid += 1
        try:
            step = self.env.step(action)
        except InvalidActionError:
            self.reject(action, node_id)
            raise
        except EnvError as exc:
            raise EpisodeEnd(exc.end_reason, exc.row_error()) from exc
        except Exception as exc:
            raise EpisodeEnd("env_error", f"{type(exc).__name__}: {exc}") from exc
        tool = step.info.get("tool")  # a coding environment's text action is a shell command
        if isinstance(tool, str):
            self._record_tool(tool, json.dumps({"command": action}), step, node_id)
        return self._took(action, valid, step, node_id)

    def execute_tool(self, call: ToolCall, node_id: int | None = None, message_seq: int | None = None) -> Step:
        """Run one tool call of a model reply and return its observation. A call that cannot run
        (arguments that are not a JSON object, a tool the environment does not have) or that the
        tool refuses is recorded invalid and answered with an error observation; the episode goes
        on (only the step cap, the environment or its end stop it)."""
        names = [t.name for t in self.env.tool_defs()]
        problem = call.parse_error
        if problem is None and call.name not in names:
            problem = f"there is no tool named {call.name!r}; the tools are: {', '.join(names)}"
        action = cut(f"{call.name} {call.arguments}", MAX_ARGUMENTS_CHARS)
        if problem is not None or call.args is None:
            self.invalid += 1
            observation = f"error: {problem}"
            self._record(action, False, observation, False, node_id)
            step = Step(observation, None, False, False, {"error": problem})
            self._record_tool(call.name, call.arguments, step, node_id, call, message_seq, step_index=self.attempts - 1)
            return step
        try:
            step = self.env.call_tool(call.name, call.args)
        except EnvError as exc:
            raise EpisodeEnd(exc.end_reason, exc.row_error()) from exc
        except Exception as exc:
            raise EpisodeEnd("env_error", f"{type(exc).__name__}: {exc}") from exc
        valid = step.info.get("error") is None
        if not valid:
            self.invalid += 1
        self._record_tool(call.name, call.arguments, step, node_id, call, message_seq)
        return self._took(action, valid, step, node_id)

    def record_not_run(self, call: ToolCall, node_id: int | None, message_seq: int) -> None:
        """The ``tool_calls`` row of a call that was never run because its reply could not be used
        (repaired, or past the repair budget): invalid, its error :data:`NOT_RUN`, ``step_index``
        the index the episode's next ``steps`` row takes (no step was taken)."""
        self.invalid += 1
        step = Step(NOT_RUN, None, False, False, {"error": NOT_RUN})
        self._record_tool(call.name, call.arguments, step, node_id, call, message_seq)

    def submit_at_limit(self, end: EpisodeEnd) -> EpisodeEnd:
        """How the episode ends when ``end`` is a limit (:func:`is_limit`): the environment hands
        in the work so far and judges it (:meth:`Environment.submit_at_limit`), and the episode
        ends ``autosubmitted``, its success the verdict and its detail the limit first
        (``episode_limit: $10.0100 spent (limit $10)``). ``end`` itself for any other end, or when
        there is nothing to hand in (no changes); an environment that breaks while handing in
        ends the episode with its own error."""
        if not is_limit(end):
            return end
        limit = f"{end.reason}: {end.detail}" if end.detail else end.reason
        try:
            step = self.env.submit_at_limit(limit)
        except EnvError as exc:
            return EpisodeEnd(exc.end_reason, exc.row_error(f"handing in the work at {limit}"))
        except Exception as exc:
            return EpisodeEnd("env_error", f"handing in the work at {limit}: {type(exc).__name__}: {exc}")
        if step is None:
            return end
        self.success = step.success
        return EpisodeEnd("autosubmitted", limit, error_kind=end.error_kind, resolved=step.success)

    def _took(self, action: str, valid: bool, step: Step, node_id: int | None) -> Step:
        """Count a step the environment took, record it and end the episode where it ends."""
        self.steps += 1
        self.observation = step.observation
        self._set_valid(step.valid_actions)
        self.success = step.success
        self._record(action, valid, step.observation, step.done, node_id)
        if step.success:
            raise EpisodeEnd("success")
        said = step.info.get("end_reason")
        if step.done and said == "agent_done":  # e.g. FEVER's wrong verdict, a coding fix that fails its tests
            raise EpisodeEnd("agent_done", f"the environment ended the episode after {self.steps} steps without success")
        if step.done and said == "episode_limit":  # the environment's own limit (a coding sandbox's wall time)
            raise EpisodeEnd("episode_limit", str(step.info.get("detail") or f"the environment's limit after {self.steps} steps"))
        if step.done or self.steps >= self.env.max_steps:
            raise EpisodeEnd("step_cap", f"{self.steps} steps (cap {self.env.max_steps})")
        return step

    def _record_tool(
        self,
        name: str,
        arguments: str,
        step: Step,
        node_id: int | None,
        call: ToolCall | None = None,
        message_seq: int | None = None,
        *,
        step_index: int | None = None,
    ) -> None:
        """The ``tool_calls`` row of one call, from what the environment reported in ``info``."""
        info = step.info
        error = info.get("error")
        exit_code = info.get("exit_code")
        self.emit(
            ToolCallRecord(
                episode_id=self.episode_id,
                index=self.tool_calls,
                step_index=self.attempts if step_index is None else step_index,
                name=cut(name, MAX_NAME_CHARS),
                arguments=cut(arguments, MAX_ARGUMENTS_CHARS),
                valid=error is None,
                call_id=cut(call.id, MAX_NAME_CHARS) if call is not None else None,
                message_seq=message_seq,
                node_id=node_id,
                error=None if error is None else str(error),
                exit_code=exit_code if isinstance(exit_code, int) else None,
                duration_s=float(info.get("duration_s", 0.0)),
                output_bytes=int(info.get("output_bytes", 0)),
                timed_out=bool(info.get("timed_out", False)),
            )
        )
        self.tool_calls += 1

    def _record(self, action: str, valid: bool, obs: str, done: bool, node_id: int | None) -> None:
        self.emit(
            StepRecord(
                episode_id=self.episode_id,
                index=self.attempts,
                env_step=self.steps,
                action=action,
                valid=valid,
                observation=obs,
                done=done,
                success=self.success,
                node_id=node_id,
            )
        )
        self.attempts += 1


@dataclass
class Episode:
    """The per-episode state an agent works with."""

    conv: Conversation
    driver: EnvDriver
    env: Environment
    emit: Emit
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.conv.record_not_run is None:
            self.conv.record_not_run = self.driver.record_not_run

    def result(self, end: EpisodeEnd, max_depth: int = 0) -> EpisodeResult:
        u = self.conv.usage
        return EpisodeResult(
            end_reason=end.reason,
            success=end.success,
            steps=self.driver.steps,
            llm_calls=u.calls,
            prompt_tokens=u.prompt_tokens,
            cached_prompt_tokens=u.cached_prompt_tokens,
            completion_tokens=u.completion_tokens,
            cost_usd=u.cost_usd,
            max_depth=max_depth,
            invalid_actions=self.driver.invalid,
            json_repairs=u.json_repairs,
            error=end.detail or None,
            error_kind=end.error_kind,
            refusal=end.refusal,
        )
