"""The environment interface every agent uses, and the errors environments raise.

An environment instance is one task instance (a Robotouille kitchen at a layout seed, an ALFWorld game).
``reset`` gives the first observation, the valid actions (None when the action space is open)
and the goal; ``step`` takes an action string that must *exactly* equal one of the valid
actions (looked up by index, never by substring). Environments whose benchmark lets any command
reach the game (ALFWorld answers "Nothing happens.") declare ``invalid_action_mode = "step"``.
"""

from __future__ import annotations

import copy
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

from recap.demo_replies import DemoReplies
from recap.demo_script import DemoScript
from recap.llm import ToolDef
from schemas.kinds import EndReason

#: the step cap of a :meth:`Environment.plan_copy` (no plan is this long)
PLAN_COPY_STEPS = 10**9


class EnvError(RuntimeError):
    """The environment failed (engine error, missing data, broken game file). ``end_reason`` is
    the episode's end reason the runtime records for it: ``env_error`` unless a subclass has its
    own (FEVER's Wikipedia errors end ``wiki_error``)."""

    end_reason: EndReason = "env_error"
    #: the failure's kind, or None; an error with a kind has a message that starts ``"KIND: "``
    #: (FEVER's ``unavailable``, the sandbox service's ``sandbox``). The pipeline reads it from the
    #: row: a kind it lists as infrastructure makes the attempt an ``infra_error`` (or a FEVER
    #: ``wiki_unavailable``) that the next resume runs again, instead of a 0 % outcome
    kind: str | None = None

    def row_error(self, what: str = "") -> str:
        """The episode's error for this failure: the message, with ``what`` (e.g. ``"reset failed"``)
        put after its kind, so the kind stays the first word."""
        text = str(self)
        if not what:
            return text
        head = f"{self.kind}: " if self.kind else ""
        if head and text.startswith(head):
            return f"{head}{what}: {text[len(head) :]}"
        return f"{what}: {text}"


class InvalidActionError(ValueError):
    """An action string that is not one of the valid actions; the state is unchanged."""


class UnknownInstanceError(ValueError):
    """An instance id or selector that names nothing; the message says what exists."""


class DataNotFoundError(FileNotFoundError):
    """A benchmark data folder is missing or is not the expected layout."""


@dataclass(frozen=True)
class Reset:
    """What :meth:`Environment.reset` returns: the first observation, the valid actions (None: an
    open action space) and the goal as text."""

    observation: str
    valid_actions: tuple[str, ...] | None
    goal: str


@dataclass(frozen=True)
class Step:
    """What :meth:`Environment.step` returns: the new observation and valid actions (None: an open
    action space), whether the episode is over (``done``) and whether the goal was reached; ``info``
    holds environment-specific extras."""

    observation: str
    valid_actions: tuple[str, ...] | None
    done: bool
    success: bool
    info: Mapping[str, Any] = field(default_factory=dict)


class Demonstration:
    """A one-shot demonstration, rendered by running the agent itself on a scripted model.

    ``make_env`` builds a fresh environment at the demonstration's start (for Robotouille the
    training kitchen on our engine; for ALFWorld a replay of recorded observations).
    ``script`` is the solved example written once (:class:`~recap.demo_script.DemoScript`);
    each agent class derives its own model replies from it. ``replies`` given here are
    hand-written replies for one method's key (``Agent.style``), in call order; they win over
    what the script would derive. Reading ``replies`` gives both (a
    :class:`~recap.demo_replies.DemoReplies`). Rendering with the agent keeps the demonstration in
    exactly the format of the agent's own prompts, for every ablation.
    """

    __slots__ = ("name", "make_env", "replies", "script")

    def __init__(
        self,
        name: str,
        make_env: Callable[[], Environment],
        replies: Mapping[str, Sequence[Mapping[str, Any]]] | None = None,
        *,
        script: DemoScript | None = None,
    ) -> None:
        self.name = name
        self.make_env = make_env
        self.script = script
        self.replies = DemoReplies(replies, script)

    def __repr__(self) -> str:
        return f"Demonstration(name={self.name!r})"


#: the spellings an environment may ask the agent-facing layer to apply (Environment.action_spelling)
ActionSpelling = Literal["as_written", "lower_first"]


def agent_action(env: Environment, action: str) -> str:
    """``action`` as the agent-facing layer hands it to ``env``: unchanged, or with its first
    character lower-cased when the environment declares ``lower_first``."""
    if env.action_spelling == "lower_first" and action:
        return action[0].lower() + action[1:]
    return action


class Environment(ABC):
    """One benchmark task instance behind a uniform interface."""

    #: stable id, e.g. ``robotouille/asynchronous/5_potato_soup@42``
    instance_id: str = ""
    benchmark: str = ""
    #: split or task family (``synchronous``, ``asynchronous``, ``heat``, ...)
    split: str = ""
    #: task name within the benchmark (``5_potato_soup``, ``pick_heat_then_place_in_recep``...)
    task: str = ""
    #: the instance's layout seed: the ``@N`` of its id (the kitchen's layout seed, a blocksworld
    #: start and goal); 0 where the benchmark has none. Not the unit's sampling seed.
    layout_seed: int = 0
    #: ``reject``: an action not in valid_actions never reaches the engine (no step is taken);
    #: ``step``: it is sent to the game, which answers and counts a step.
    invalid_action_mode: Literal["reject", "step"] = "reject"
    #: True when an observation shows only part of the state (ALFWorld: what is at the agent's
    #: location), so a context opened later also needs the episode's first observation; False
    #: when every observation shows the whole state (Robotouille, blocksworld).
    partially_observed: bool = False
    #: True when every observation already ends with the currently valid actions (ALFWorld with
    #: ``show_valid_actions``), so feedback that names them need not repeat the list
    lists_valid_actions: bool = False
    optimal_steps: int | None = None
    #: how the agent-facing layer spells a model's action before the engine sees it
    #: (:func:`agent_action`): ``as_written``, or ``lower_first`` (FEVER: the release's runner
    #: lower-cases the first character, fever-recap/hotpotqa/hotpotqa_simulator.py:41, so
    #: ``Search[X]`` reaches the engine as ``search[X]``; the engine itself takes actions as written)
    action_spelling: ActionSpelling = "as_written"
    #: environment steps allowed (ceil(optimal x multiplier), or a benchmark's fixed cap)
    max_steps: int = 50
    #: when True, the episode is re-checked against max_steps by the agent; envs may also end it
    test_double: bool = False

    @abstractmethod
    def reset(self) -> Reset: ...

    @abstractmethod
    def step(self, action: str) -> Step:
        """Apply ``action``. Raises InvalidActionError (state unchanged) in ``reject`` mode."""

    @abstractmethod
    def rules(self) -> str:
        """The environment description and rules, in the words of our prompts."""

    @abstractmethod
    def demonstration(self) -> Demonstration | None:
        """The one-shot demonstration used for this instance (None: zero-shot)."""

    def plan_copy(self) -> Environment:
        """A copy of this environment for checking a whole plan before it runs: it takes steps
        past the goal and past the step cap, as the released I/O agents' check steps its engine
        copy through every planned action (robotouille-baselines/agents/IO_agent.py:174-187).
        Raises whatever :func:`copy.deepcopy` raises for an engine that cannot be copied; an
        environment that refuses steps once its episode is over overrides this."""
        sim = copy.deepcopy(self)
        sim.max_steps = PLAN_COPY_STEPS
        return sim

    # -- tool calls (coding environments) --------------------------------------------------------
    def tool_defs(self) -> tuple[ToolDef, ...]:
        """The tools a model calls as its actions (OpenAI function tools: ``bash``, a file viewer,
        an editor, ``submit``); empty for an environment whose actions are text. An environment
        with tools has an open action space: ``valid_actions`` is None and any call of one of its
        tools with arguments it accepts is a valid action (the paper's SWE-bench protocol)."""
        return ()

    def call_tool(self, name: str, args: Mapping[str, Any]) -> Step:
        """Run one tool call and return its observation as a :class:`Step`. ``info`` carries what
        the ``tool_calls`` table records: ``exit_code`` (None: no process, or killed),
        ``duration_s``, ``output_bytes`` (before any cap), ``timed_out``, and ``error`` (a call
        the tool refused: unknown tool, missing argument, a path outside the repository; the
        observation says why, the episode goes on). Raises :class:`EnvError` only when the
        environment itself broke (the sandbox is gone)."""
        raise InvalidActionError(f"{name}: this environment has no tools")

    def submit_at_limit(self, limit: str) -> Step | None:
        """Hand in the work so far when a limit ends the episode (``limit``: which one, one line)
        and judge it: SWE-agent's autosubmission (swebench-recap/sweagent/agent/agents.py:888-933),
        which a coding environment does with a non-empty diff. The returned step's ``success`` is
        the verdict; None when there is nothing to hand in (no changes, an environment without
        submissions: the default). Raises :class:`EnvError` when the environment broke."""
        return None

    def failure_hints(self) -> str:
        """Hints shown after an invalid action (e.g. occupied station, inexact name); may be ''."""
        return ""

    def expert_plan(self) -> list[str] | None:
        """Remaining actions of an expert solution from the *current* state (None: no expert).

        Used only by the offline expert model (a test double) and solvability checks.
        """
        return None

    @property
    def steps_taken(self) -> int:
        return getattr(self, "_steps_taken", 0)

    def take_records(self, episode_id: str, run_id: str) -> list[Any]:
        """Table records the environment made since the last call (schemas.records: FEVER's
        ``wiki_pages``/``wiki_requests`` rows of the pages it read), for the episode worker to
        write into run ``run_id`` beside the episode's own; each record is handed over once.
        Default: none."""
        return []

    def close(self) -> None:
        """Release engine resources."""
