"""The ``mini_swe`` method: mini-SWE-agent's own agent loop, the paper's ReAct baseline on SWE-bench
as the paper ran it (the loop and its use of our client and sandbox: :mod:`.mini_swe_package`).

Why a method of its own beside ``react`` (whose coding loop, :mod:`recap.baselines.react_swe`, is
our rewrite of the same loop in our words): the two are not the same baseline. ``react`` on a
coding benchmark is ReAct in our prompts, comparable across benchmarks; ``mini_swe`` is the
package, with its prompts, so a sweep can reproduce the number in the paper's ReAct column on
SWE-bench (mini-SWE-agent's 39.58%) and set it beside ours. A sweep that wants that column labels
the arm (``{name: mini_swe, label: react}``); the method name in the rows says which loop ran.

Settings (the package's SWE-bench configuration where it has one): temperature 0; no output cap
per call (the package sends none); the whole history every call (``window`` has no effect; a
context overflow ends the episode); text replies (``json_mode`` off, refused on). Its limits come
from the run's caps: ``step_limit`` is the episode's call cap (by default the step cap, the
package's 250 for 250 commands: it counts model calls, format errors included) and ``cost_limit``
is ``max_episode_cost_usd`` ($3 by default, the package's; null: no limit). ``max_json_repairs``
has no effect: the package allows any number of format errors (each is counted in
``json_repairs``). It runs only on an environment with tools (a coding benchmark).
"""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass
from typing import ClassVar

from recap.agent import Agent
from recap.config import AgentConfig, ConfigError
from recap.env import Environment, Reset
from recap.runtime import Episode, EpisodeEnd

#: the package's import name
PACKAGE = "minisweagent"
#: the whole history: mini-SWE-agent sends every message on every call
UNBOUNDED_WINDOW = 10**9
#: the package's SWE-bench cost limit (config/extra/swebench.yaml: ``cost_limit: 3.``)
PACKAGE_COST_LIMIT_USD = 3.0


@dataclass(frozen=True)
class MiniSweConfig(AgentConfig):
    """mini-SWE-agent's settings (see the module docstring for what each field does here)."""

    temperature: float | None = 0.0
    max_tokens: int | None = None
    json_mode: bool = False
    max_episode_cost_usd: float | None = PACKAGE_COST_LIMIT_USD

    def history_window(self) -> int:
        return UNBOUNDED_WINDOW

    def history_counts_pins(self) -> bool:
        return False

    def validate(self) -> None:
        super().validate()
        if self.json_mode:
            raise ConfigError("mini_swe replies are plain text (a THOUGHT and one bash block): json_mode must be false")
        if importlib.util.find_spec(PACKAGE) is None:  # refused when the sweep is planned, before any call
            raise ConfigError(f"mini_swe needs the mini-SWE-agent package: pip install 'recap-eval[swe]' (no module {PACKAGE!r})")


class MiniSweAgent(Agent):
    """mini-SWE-agent's ``DefaultAgent`` with its SWE-bench configuration (:mod:`.mini_swe_package`)."""

    style = "mini_swe"
    config_cls = MiniSweConfig
    expected_format = "THOUGHT: <your reasoning>\n\n```bash\n<one command>\n```"
    #: what the offline test doubles fill (written as a THOUGHT and one bash block)
    reply_fields: ClassVar[tuple[str, ...]] = ("think", "action")
    #: one call per command
    estimate_calls_per_step = (1.0, 1.0)
    config: MiniSweConfig

    def call_cap(self, max_steps: int) -> int:
        """The package's ``step_limit`` for a step cap of ``max_steps`` commands: as many model calls."""
        return max_steps

    def refuses_env(self, env: Environment) -> str | None:
        """mini-SWE-agent acts with shell commands in a repository: only a coding environment (one
        with tools) can host it; preflight refuses any other before anything runs."""
        if env.tool_defs():
            return None
        return f"mini_swe runs only on a coding benchmark (swe, swe-verified), not on {env.benchmark}"

    def play(self, ep: Episode, reset: Reset) -> None:
        refused = self.refuses_env(ep.env)
        if refused is not None:
            raise EpisodeEnd("env_error", refused)
        from workers.agents.mini_swe_package import play_package  # the package only when an episode plays

        cfg = ep.conv.config
        play_package(ep, reset, step_limit=int(cfg.max_llm_calls or 0), cost_limit=float(cfg.max_episode_cost_usd or 0.0))
