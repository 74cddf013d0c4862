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

``package_config``: whose SWE-bench configuration the loop runs: ``installed`` (the installed
package's, the ``paper`` profile and the default) or ``1.0.0`` (``profile: released``):
mini-swe-agent 1.0.0's, the version of the leaderboard run behind the paper's 39.58 %
(``workers/agents/mini_swe_1_0_0/``, :mod:`.mini_swe_package`), with its own ``step_limit`` (0:
none; the run's call cap stays a safety bound) and ``cost_limit`` ($3).
"""

from __future__ import annotations

import importlib.util
import json
from dataclasses import dataclass
from typing import Any, ClassVar

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
#: ``package_config`` values (workers.agents.mini_swe_package.PACKAGE_CONFIGS, kept here so that
#: building a config imports neither the package nor yaml): the installed package's, or 1.0.0's
INSTALLED, RELEASED_VERSION = "installed", "1.0.0"


@dataclass(frozen=True)
class MiniSweConfig(AgentConfig):
    """mini-SWE-agent's settings (see the module docstring for what each field does here)."""

    temperature: float | None = 0.0
    max_tokens: int | None = None
    json_mode: bool = False
    max_episode_cost_usd: float | None = PACKAGE_COST_LIMIT_USD
    #: whose SWE-bench configuration runs: the installed package's, or 1.0.0's (``released``).
    #: Left out of :meth:`to_json` while ``installed``, so units planned before it keep their hash
    package_config: str = INSTALLED

    @classmethod
    def profile_defaults(cls, profile: str, ablation: str | None) -> dict[str, Any]:
        """``released``: mini-swe-agent 1.0.0's configuration and its ``cost_limit: 3.``
        (mini_swe_1_0_0/swebench.yaml)."""
        out = super().profile_defaults(profile, ablation)
        if profile == "released":
            out.update(package_config=RELEASED_VERSION, max_episode_cost_usd=PACKAGE_COST_LIMIT_USD)
        return out

    def to_json(self) -> str:
        values = json.loads(super().to_json())
        if values.get("package_config") == INSTALLED:
            del values["package_config"]
        return json.dumps(values, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> MiniSweConfig:
        try:
            values = json.loads(text)
        except ValueError:
            values = None
        if isinstance(values, dict):
            text = json.dumps({"package_config": INSTALLED, **values}, sort_keys=True)
        cfg = super().from_json(text)
        assert isinstance(cfg, MiniSweConfig)
        return cfg

    def history_window(self) -> int:
        return UNBOUNDED_WINDOW

    def history_counts_pins(self) -> bool:
        return False

    def validate(self) -> None:
        super().validate()
        if self.json_mode:
            raise ConfigError("mini_swe replies are plain text (a THOUGHT and one bash block): json_mode must be false")
        if self.package_config not in (INSTALLED, RELEASED_VERSION):
            raise ConfigError(f"package_config must be {INSTALLED} or {RELEASED_VERSION}, got {self.package_config!r}")
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
        from workers.agents.mini_swe_package import load_package, play_package  # the package only when an episode plays

        cfg = ep.conv.config
        package = load_package(getattr(cfg, "package_config", INSTALLED))
        play_package(
            ep,
            reset,
            step_limit=int(cfg.max_llm_calls or 0),
            cost_limit=float(cfg.max_episode_cost_usd or 0.0),
            package=package,
        )
