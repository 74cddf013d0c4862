"""Agent settings: one dataclass per method, ablations as fields, and the two named profiles.

Ablations are configuration of one agent, never copies of it. ``paper`` follows the paper
(K = 64 rounds = 128 messages, temperature 0.5, the provider's output cap); ``released`` follows
the authors' released code (K = 128 messages counting the pins, ReCAP's temperature not sent,
0.7 for the Robotouille baselines). One unit of ``window`` is one message.

A profile can depend on the ablation (the released code runs its ablation variants without the
shortcut) and on the benchmark (the paper runs Robotouille's own ReAct protocol on Robotouille
and Yao et al.'s on ALFWorld). Each config class says what a profile means for it anywhere in
:meth:`AgentConfig.profile_defaults`; each benchmark declares where its own protocol differs
(:class:`BenchmarkProtocol`, e.g. ``workers/envs/robotouille/protocol.py``), so
recap never switches on a benchmark's name; the README's protocol table lists every item.

Two settings are *derived* when left at None, from facts known only when an episode starts:

* ``max_llm_calls``: from the environment's step cap by the method's own formula
  (:meth:`recap.agent.Agent.call_cap`), so no method is cut by calls before it could use its
  step budget;
* ``max_tokens``: each config class has a default output cap measured from the longest expert
  reply in its reply format (``bench/protocol.py`` prints the measurement). Both profiles set
  None instead: the request carries the model's own maximum output
  (:func:`workers.llm.providers.model_max_output_tokens`), so no reply the provider would have
  finished is cut by a cap of ours (the paper used the provider default).
"""

from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass
from typing import Any, Literal

from schemas.ranges import range_problem

PROFILES: dict[str, dict[str, Any]] = {
    # the paper: K = 64 back-and-forth rounds (Sec. "Sliding Window"), i.e. 128 messages in our
    # unit (``window`` counts messages, recap/history.py), the released main value (ctx_len 128,
    # robotouille-recap/main.py:55); T = 0.5 for every method and the provider's default output
    # cap (appendix "Robotouille Experiment Details"). Trimming stays the paper's ``pair``
    # although ``block`` is cheaper under every provider's prompt caching (bench/cost.py; the
    # README's "Cheap runs" says when to set window_mode: block instead)
    "paper": {"window": 128, "temperature": 0.5, "window_mode": "pair", "max_tokens": None},
    # the released code: K = 128 messages counted over the whole history, pins included
    # (robotouille-recap/MATRIX/MATRIX/chatbot.py:72-74, alfworld-recap/MATRIX/MATRIX/chatbot.py:73-74),
    # no temperature and no output cap sent (chatbot.py:85-90 of both); each method's own
    # profile_defaults says where the released baselines differ (temperature 0.7 on Robotouille)
    "released": {"window": 128, "temperature": None, "window_counts_pins": True, "window_mode": "pair", "max_tokens": None},
}

#: what the paper's SWE-bench runs set for every method, under either profile, for a coding
#: benchmark's protocol to add in :meth:`BenchmarkProtocol.profile_settings` (ReCAP's tool-call
#: mode and mini-SWE-agent's ReAct): temperature 0 ("temperature set to zero", section
#: "SWE-bench" and the appendix "SWE-bench Verified Experiment Details"; no demonstration there
#: either, which the environment declares by having none)
CODING_PROFILE: dict[str, Any] = {"temperature": 0.0}

#: whether observations list the currently valid actions, where a benchmark makes that optional
#: (ALFWorld): ``shown`` in the episode and in the one-shot demonstration, ``episode`` in the
#: episode only (the demonstration stays as written), ``hidden`` nowhere; None: the benchmark's
#: own choice for the method (workers.envs.alfworld.benchmark.show_valid_actions_for)
ValidActions = Literal["shown", "episode", "hidden"]

#: how a demonstration shows the example's observations (see recap.agent.ElidedObservations)
DemoObservations = Literal["all", "first", "none"]
#: what the one-shot demonstration puts in place of an observation it leaves out
OMITTED_OBSERVATION = "(observation left out of this example)"


class ConfigError(ValueError):
    """An unknown or out-of-range agent setting."""


class BenchmarkProtocol:
    """What a benchmark declares about how the methods run on it, so recap never compares a
    benchmark's name: a method's profile can mean other settings on another benchmark (the paper
    runs Robotouille's own ReAct protocol on Robotouille and Yao et al.'s on ALFWorld; the
    authors' released prompts exist for two benchmarks). ``workers.envs.registry.Benchmark``
    subclasses this, each built-in benchmark's folder holds its protocol
    (``workers/envs/<name>/protocol.py``), and :func:`build_config` asks it. Each hook's
    default says "nothing special here", so a new benchmark overrides only what it has to say."""

    name: str = ""

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """What ``profile`` sets for a method (its config class ``config_cls``) on this benchmark,
        given what it sets anywhere (``generic``: the method's own
        :meth:`recap.config.AgentConfig.profile_defaults`). The result replaces ``generic``, so a
        benchmark may add, change or drop settings. Default: ``generic`` unchanged."""
        return generic

    def release_prompt_settings(self, config_cls: type[AgentConfig]) -> dict[str, Any]:
        """Settings the authors' released prompt for a method implies on this benchmark (the reply
        format it asks for); ``prompts: release`` applies them. Default: none (no released
        prompts, or ones that imply nothing)."""
        return {}


#: settings added after units were first planned, each with the value it stands for when left
#: out: :meth:`AgentConfig.to_json` leaves a setting out while it holds that value and
#: :meth:`AgentConfig.from_json` fills it in, so the hashes of units planned before the setting
#: existed do not change
LATE_SETTINGS: dict[str, Any] = {
    "prompts": "ours",
    "context_overflow": "drop",
    "tool_calls_per_reply": "any",
    "reply_schema": False,
    "submit_at_limit": True,
    # the released FEVER ReCAP loop's settings (workers/envs/fever/protocol.py RECAP_RELEASED)
    "action_pattern": None,
    "final_answer": False,
    "pin_task": True,
    "observation_drop": "",
    "resend_bad_replies": False,
    "safety_steps": None,
}


@dataclass(frozen=True)
class AgentConfig:
    """Settings every agent shares: the window, generation settings and per-episode caps."""

    window: int = 64
    #: see recap/history.py (``prompt``: the released FEVER ReCAP's cut before each prompt)
    window_mode: Literal["pair", "block", "prompt"] = "pair"
    window_block: int | None = None
    #: True: K bounds the whole history, pins included (the released code); False: K bounds
    #: the messages after the two pins (the paper's reading)
    window_counts_pins: bool = False
    temperature: float | None = 0.5
    #: output-token cap per call. Each method's default is measured by bench/protocol.py: twice
    #: the longest expert reply of any instance in the method's reply format, rounded up to 512,
    #: and at least 1024 (a reply that still hits it ends the episode as ``truncated``)
    max_tokens: int | None = 1024
    json_mode: bool = True
    max_json_repairs: int = 3
    #: None derives the cap from the step cap (recap.agent.Agent.call_cap); a number fixes it
    max_llm_calls: int | None = None
    max_episode_tokens: int | None = None
    max_episode_cost_usd: float | None = None
    context_drop: int = 32
    #: the one-shot demonstration shows every observation (all), only the first one (first),
    #: or none of them (none); left-out observations read OMITTED_OBSERVATION
    demo_observations: DemoObservations = "all"
    #: see ValidActions (None: the benchmark decides per method)
    valid_actions: ValidActions | None = None
    #: whose prompt text the episode pins first: ``ours`` (our demonstration), or the authors'
    #: released files (``release:<sha256 of the text>``, set by the planner from a sweep's
    #: ``prompts: release``; ``release`` until the digest is known). Left out of :meth:`to_json`
    #: while ``ours``, so the hashes of units planned before it existed do not change.
    prompts: str = "ours"
    #: what a context overflow does: ``drop`` the oldest unpinned messages and ask again (the
    #: paper's reading), or ``end`` the episode (SWE-agent's ``exit_context``, after which the
    #: work so far is handed in: swebench-recap/sweagent/agent/agents.py:1272-1276). Left out of
    #: :meth:`to_json` while ``drop`` (:data:`LATE_SETTINGS`)
    context_overflow: Literal["drop", "end"] = "drop"
    #: at a limit (cost, tokens, calls, steps, time, context), hand in the work so far and have
    #: it judged where the environment has any (SWE-agent's autosubmission,
    #: swebench-recap/sweagent/agent/agents.py:888-933): the default under every profile. False
    #: for a loop that submitted nothing at its limits (mini-swe-agent 1.0.0, :mod:`workers.agents.mini_swe`).
    #: Left out of :meth:`to_json` while True (:data:`LATE_SETTINGS`)
    submit_at_limit: bool = True

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        """What ``profile`` sets for this method beyond PROFILES on any benchmark (the method's own
        protocol); a benchmark adjusts it where its protocol differs
        (:meth:`BenchmarkProtocol.profile_settings`). Subclasses extend it."""
        return {}

    def validate(self) -> None:
        if self.window < 2:
            raise ConfigError(f"window must be >= 2 messages, got {self.window}")
        if self.window_mode not in ("pair", "block", "prompt"):
            raise ConfigError(f"window_mode must be 'pair', 'block' or 'prompt', got {self.window_mode!r}")
        if self.temperature is not None and not 0 <= self.temperature <= 2:
            raise ConfigError(f"temperature must be in [0, 2], got {self.temperature}")
        if self.max_json_repairs < 0:
            raise ConfigError("max_json_repairs must be >= 0")
        if self.max_llm_calls is not None and self.max_llm_calls < 1:
            raise ConfigError("max_llm_calls must be >= 1 or null (derived from the step cap)")
        if self.max_tokens is not None and self.max_tokens < 1:
            raise ConfigError("max_tokens must be >= 1 or null (the model's own cap)")
        if self.context_drop < 2:
            raise ConfigError("context_drop must be >= 2")
        if self.demo_observations not in ("all", "first", "none"):
            raise ConfigError(f"demo_observations must be all, first or none, got {self.demo_observations!r}")
        if self.window_counts_pins and self.window < 4:
            raise ConfigError("window must be >= 4 messages when it counts the two pins")
        if self.valid_actions not in (None, "shown", "episode", "hidden"):
            raise ConfigError(f"valid_actions must be shown, episode, hidden or null, got {self.valid_actions!r}")
        if not re.fullmatch(r"ours|release(:[0-9a-f]{64})?", str(self.prompts)):
            raise ConfigError(f"prompts must be ours or release, got {self.prompts!r}")
        if self.context_overflow not in ("drop", "end"):
            raise ConfigError(f"context_overflow must be drop or end, got {self.context_overflow!r}")

    def history_window(self) -> int:
        """K as the shared history applies it (ReAct's ``history: last`` narrows it)."""
        return self.window

    def history_counts_pins(self) -> bool:
        return self.window_counts_pins

    def applied_window(self) -> int | None:
        """The window the episode's history applies, in messages, or None for no window: the
        whole history (ReAct/Act's ``history: all``, a window at the largest allowed setting, a
        bound no episode reaches: ReCAP as swebench-recap ran it)."""
        k = self.history_window()
        return None if k >= SETTING_BOUNDS["window"][1] else k

    def recorded_json(self) -> str:
        """The settings as the episode applies them, for its rows (``method_config``): :meth:`to_json`
        with ``window`` the one applied (:meth:`applied_window`; ``null`` for no window), not the
        setting that another one overrides (Act's whole history under ``history: all``). The
        unit's hash keeps covering :meth:`to_json`: the ids of planned units do not change."""
        values = json.loads(self.to_json())
        values["window"] = self.applied_window()
        return json.dumps(values, sort_keys=True)

    def history_keep(self) -> int:
        """Windowed messages at the head of the history that trimming never drops (ReAct's
        released Robotouille window keeps its first reply); 0 for every other method."""
        return 0

    def to_json(self) -> str:
        """Canonical JSON (sorted keys): part of a unit's content hash and of episode rows."""
        values = dataclasses.asdict(self)
        for name, default in LATE_SETTINGS.items():
            if name in values and values[name] == default:
                del values[name]
        return json.dumps(values, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> AgentConfig:
        """The config :meth:`to_json` wrote, exactly (``from_json(c.to_json()) == c``).

        Why: a unit carries its resolved settings as this JSON (it is what its hash covers), so
        a worker builds the agent from it instead of re-resolving profile + ablation + settings
        and possibly getting something else. Every field must be present: a unit written by
        another version of a config class fails here, by name, rather than running with defaults."""
        try:
            values = json.loads(text)
        except ValueError as exc:
            raise ConfigError(f"{cls.__name__}: resolved settings are not JSON: {exc}") from None
        if not isinstance(values, dict):
            raise ConfigError(f"{cls.__name__}: resolved settings must be a JSON object")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown, missing = sorted(set(values) - names), sorted(names - set(values) - set(LATE_SETTINGS))
        if unknown or missing:
            raise ConfigError(
                f"{cls.__name__}: resolved settings do not match this version "
                f"(unknown: {', '.join(unknown) or '-'}; missing: {', '.join(missing) or '-'})"
            )
        return cls(**values)


@dataclass(frozen=True)
class ReCAPConfig(AgentConfig):
    """ReCAP settings. ``max_level`` caps the tree (root = level 1; the paper's level_2..5);
    ``think`` is ``latest`` (paper), ``none`` (no_think) or ``many`` (think_many);
    ``name_only`` makes return prompts carry only the finished and the current task."""

    #: ReCAP's root may list every action of a long recipe as subtasks: the longest expert plan
    #: (async 9 @420, 103 actions) is 1,283 tokens with a think
    max_tokens: int | None = 3072
    max_level: int | None = None
    think: Literal["latest", "none", "many"] = "latest"
    name_only: bool = False
    reminder_period: int | None = 10
    #: what the reminder period counts: ``calls`` (LLM calls, the paper) or ``iterations``
    #: (control-loop iterations: every child entered, shortcuts included, and every return;
    #: the released code), or ``nth_call`` (the prompt of call number period, 2 x period, ...:
    #: the released FEVER loop, fever-recap/MATRIX/MATRIX/chatbot.py:350-360). The reminder goes
    #: on whichever prompt is sent next.
    reminder_on: Literal["calls", "iterations", "nth_call"] = "calls"
    shortcut: bool = True
    #: the released code leaves a shortcut's trace in the history (the descend prompt and a
    #: synthetic reply naming the action, no call); the paper describes no such messages
    shortcut_trace: bool = False
    #: a one-item list reaches the environment only when the item (stripped) matches this regex;
    #: otherwise it is a leaf failure that uses no step (None: every item the environment accepts,
    #: the paper). The released FEVER loop's check (fever-recap/MATRIX/MATRIX/chatbot.py:308-312,
    #: 379-381, 412-423); it also makes a one-item root list a leaf, as that loop does
    action_pattern: str | None = None
    #: when the root's list empties, one more call asks for the final answer and its first
    #: subtask is sent as the last action (fever-recap/MATRIX/MATRIX/chatbot.py:470-478)
    final_answer: bool = False
    #: False: the task prompt is the first windowed message instead of a pin, so the window drops
    #: it first and only the demonstration stays (fever-recap/MATRIX/MATRIX/chatbot.py:42-44)
    pin_task: bool = True
    #: text deleted from every observation before a prompt shows it (the released FEVER runner
    #: deletes the two characters backslash-n: fever-recap/hotpotqa/hotpotqa_simulator.py:42)
    observation_drop: str = ""
    #: a reply that is not strict JSON (code fences removed) or lacks ``subtasks`` gets an error
    #: message and the same prompt again, bounded only by the call cap, instead of our repair
    #: message (fever-recap/MATRIX/MATRIX/chatbot.py:370-371, 461-469: the loop runs again)
    resend_bad_replies: bool = False
    #: None: the benchmark's step cap; a number: the released code has no step cap
    #: (hotpotqa_simulator.py:22,33 never counts), so this safety bound replaces it and an
    #: episode it ends says so in its row (end reason step_cap/call_cap, error "safety bound ...")
    safety_steps: int | None = None
    #: tool-call mode: ``any`` number of tool calls per reply, each run in order (the paper is
    #: silent), or exactly ``one`` per reply that calls tools, a reply with several re-asked
    #: (SWE-agent's function-calling parser, swebench-recap/sweagent/tools/parsing.py:439-449)
    tool_calls_per_reply: Literal["any", "one"] = "any"
    #: tool-call mode: ask for the ``{think, subtasks}`` reply under a strict JSON schema
    #: (``response_format`` ``json_schema``, swebench-recap/sweagent/agent/models.py:707-731)
    #: where the provider supports it, plain JSON otherwise; False: no response format
    reply_schema: bool = False

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        out = super().profile_defaults(profile, ablation)
        if profile == "released":
            # no temperature in ReCAP's released calls (robotouille-recap/MATRIX/MATRIX/chatbot.py:88
            # has it commented out; alfworld-recap/MATRIX/MATRIX/chatbot.py:79-83 sends none)
            out.update(reminder_on="iterations", shortcut_trace=True, temperature=None)
            if ablation not in (None, "original"):
                out["shortcut"] = False  # the released ablation variants have no shortcut
        return out

    def validate(self) -> None:
        super().validate()
        if self.max_level is not None and self.max_level < 2:
            raise ConfigError(f"max_level must be >= 2 (root is level 1), got {self.max_level}")
        if self.think not in ("latest", "none", "many"):
            raise ConfigError(f"think must be latest, none or many, got {self.think!r}")
        if self.reminder_period is not None and self.reminder_period < 1:
            raise ConfigError("reminder_period must be >= 1 or null")
        if self.reminder_on not in ("calls", "iterations", "nth_call"):
            raise ConfigError(f"reminder_on must be calls, iterations or nth_call, got {self.reminder_on!r}")
        if self.tool_calls_per_reply not in ("any", "one"):
            raise ConfigError(f"tool_calls_per_reply must be any or one, got {self.tool_calls_per_reply!r}")
        if self.action_pattern is not None:
            try:
                re.compile(self.action_pattern)
            except re.error as exc:
                raise ConfigError(f"action_pattern is not a regular expression: {exc}") from None
        if self.safety_steps is not None and self.safety_steps < 1:
            raise ConfigError("safety_steps must be >= 1 or null (the benchmark's step cap)")


#: the paper's ablation names, as settings of ReCAPConfig
ABLATIONS: dict[str, dict[str, Any]] = {
    "original": {},
    "no_think": {"think": "none"},
    "think_many": {"think": "many"},
    "name_only": {"name_only": True},
    "level_2": {"max_level": 2},
    "level_3": {"max_level": 3},
    "level_4": {"max_level": 4},
    "level_5": {"max_level": 5},
    "no_shortcut": {"shortcut": False},
}


#: The range of every number setting of the built-in methods (both ends inclusive), checked by
#: :func:`build_config` after the method's own checks, so a sweep's ``settings`` can hold no
#: number out of range (``window: 10000000`` would keep every message of an episode). A number
#: setting of a built-in config without an entry fails tests/pipeline/test_spec_bounds.py;
#: an extension method's own settings are its own to check.
SETTING_BOUNDS: dict[str, tuple[float, float]] = {
    "window": (2, 100_000),
    "window_block": (1, 100_000),
    "temperature": (0, 2),
    "max_tokens": (1, 262_144),
    "max_json_repairs": (0, 100),
    "max_llm_calls": (1, 1_000_000),
    "max_episode_tokens": (1, 10**10),
    "max_episode_cost_usd": (1e-6, 1_000_000),
    "context_drop": (2, 100_000),
    "max_level": (2, 100),
    "reminder_period": (1, 100_000),
    "safety_steps": (1, 100_000),
    "max_depth": (1, 100),
    "executor_steps": (1, 100_000),
    "executor_patience": (1, 100_000),
    "executor_window": (2, 100_000),
    "planner_temperature": (0, 2),
    "invalid_streak": (1, 100_000),
    "invalid_rounds": (1, 100_000),
}


def check_setting_ranges(cfg: AgentConfig) -> None:
    """Every number setting of ``cfg`` that :data:`SETTING_BOUNDS` names is a number (an integer
    where the default is one; never true/false) within its range; raises ConfigError with the
    range in the message."""
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if f.name not in SETTING_BOUNDS or value is None:
            continue
        if isinstance(value, str) and "Literal" in str(f.type):
            continue  # a named choice beside the number (ADaPT's planner_temperature: same): validate() checks it
        problem = range_problem(value, "int" in str(f.type), *SETTING_BOUNDS[f.name])
        if problem is not None:
            raise ConfigError(f"{f.name} {problem}")


def release_settings(cls: type[AgentConfig], benchmark: BenchmarkProtocol | None, overrides: dict[str, Any]) -> dict[str, Any]:
    """What ``prompts: release`` implies for ``cls`` on ``benchmark`` (the reply format the
    released prompt asks for, :meth:`BenchmarkProtocol.release_prompt_settings`);
    ConfigError, one line, when an explicit setting contradicts it."""
    implied = benchmark.release_prompt_settings(cls) if benchmark is not None else {}
    clash = sorted(k for k, v in implied.items() if k in overrides and overrides[k] != v)
    if clash:
        wants = ", ".join(f"{k}: {json.dumps(implied[k])}" for k in clash)
        what = "reply format" if set(clash) <= {"reply_format", "json_mode", "text_layout"} else "settings"
        raise ConfigError(f"prompts: release asks for the released {what} ({wants}); drop the contradicting setting")
    return implied


def build_config(
    cls: type[AgentConfig],
    profile: str | None = None,
    ablation: str | None = None,
    benchmark: BenchmarkProtocol | None = None,
    **overrides: Any,
) -> AgentConfig:
    """Profile defaults (generic, then the method's own, as ``benchmark`` declares them for
    itself), then an ablation, then explicit overrides; unknown names are errors. ``benchmark``
    is the benchmark's protocol object (``workers.envs.registry.get_benchmark(name)``), not
    its name: recap learns what a benchmark means only from what it declares."""
    if isinstance(benchmark, str):
        raise TypeError(f"build_config takes a benchmark's protocol (get_benchmark({benchmark!r})), not its name")
    values: dict[str, Any] = {}
    if profile is not None:
        if profile not in PROFILES:
            raise ConfigError(f"unknown profile {profile!r}; known: {', '.join(PROFILES)}")
        values.update(PROFILES[profile])
        own = cls.profile_defaults(profile, ablation)
        values.update(benchmark.profile_settings(cls, profile, ablation, own) if benchmark is not None else own)
    if ablation is not None:
        if ablation not in ABLATIONS:
            raise ConfigError(f"unknown ablation {ablation!r}; known: {', '.join(ABLATIONS)}")
        if cls is not ReCAPConfig and ABLATIONS[ablation]:
            raise ConfigError(f"ablation {ablation!r} applies to recap only")
        values.update(ABLATIONS[ablation])
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - names)
    if unknown:
        raise ConfigError(
            f"unknown setting(s) {', '.join(unknown)} for {cls.__name__}; known: {', '.join(sorted(names - {'prompts'}))}"
        )
    if str(overrides.get("prompts", "ours")).startswith("release"):
        values.update(release_settings(cls, benchmark, overrides))
    values.update(overrides)
    cfg = cls(**values)
    cfg.validate()
    check_setting_ranges(cfg)
    return cfg
