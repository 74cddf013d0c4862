"""mini-SWE-agent's own loop with our model client and our environment (the ``mini_swe`` method).

Why the package and not a copy of its loop: the paper's ReAct result on SWE-bench Verified is
mini-SWE-agent's published 39.58% with GPT-4.1 (section "Baselines", appendix "SWE-bench Verified
Experiment Details", leaderboard retrieved Sept 17, 2025: the 1.x series). Running its
``DefaultAgent`` with its own ``config/extra/swebench.yaml`` keeps every prompt, the action regex,
the observation and format-error templates, the submit rule and the limits exactly as the package
has them; only two things are ours, and they implement the package's own protocols:

* :class:`GatewayModel` (its ``Model``: ``query(messages) -> {"content"}``, ``cost``, ``n_calls``,
  ``get_template_vars``) sends each query through the episode's :class:`recap.runtime.Conversation`
  with the package's messages as the history, so every call is capped, budgeted, rate-limited,
  cached and recorded (``llm_calls``, ``messages``) like any agent's. The offline test doubles
  answer it from the hints (``text_layout: bash_block``, ``reply_fields`` think/action);
* :class:`SandboxEnvironment` (its ``Environment``: ``execute(command, cwd) -> {"output",
  "returncode"}``, ``get_template_vars``) runs each command through
  :meth:`recap.runtime.EnvDriver.execute`, so ``steps`` and ``tool_calls`` rows are written and the
  environment's limits apply. When our environment ends the episode (the submit sentinel, a
  limit), it raises the package's ``Submitted`` / ``LimitsExceeded`` so the package's loop ends the
  way it ends itself, and the episode then ends with our environment's reason.

What differs from the package run as its own program (said where it happens): the commands run in
our sandbox (its working folder replaces ``/testbed`` in the task text; its own output cap and
timeout apply before the package's templates see the output); the submission is judged from the
repository's diff by our environment, not from the sentinel command's printed diff; a context
overflow ends the episode (``llm_error``) instead of crashing the package's process.

Which configuration (``MiniSweConfig.package_config``): ``installed``, the installed package's own
``swebench.yaml`` (the ``paper`` profile: today's package); or ``1.0.0`` (``profile: released``),
the configuration of mini-swe-agent 1.0.0, the version of the leaderboard run behind the paper's
39.58 % (``20250726_mini-v1.0.0_gpt-4.1-2025-04-14``), shipped in ``mini_swe_1_0_0/`` (MIT, with its
licence and the wheel's digest: its README) and run on whatever version is installed: its
templates, its action regex and timeout template (1.0.0's code defaults), its ``step_limit: 0.``
(none: the run's own call cap stays as a safety bound, ``call_cap`` when it binds), its
``cost_limit: 3.`` and its submit line ``MICRO_SWE_AGENT_FINAL_OUTPUT``, which our environment
then submits on (the installed loop's own submit lines, which 1.0.0 never accepted, are not
checked). 1.0.0 rendered its templates with undefined names left empty, so its task text's
``{{working_dir}}`` (a name none of its environments defined) is rendered empty here too, and
sent its system text unrendered (:func:`_as_1_0_0`).

Importing the package prints a banner, creates a per-user config folder and loads a ``.env`` from
it; :func:`load_package` silences the banner and points the folder at an empty temporary one, so
nothing of a user's mini-SWE-agent setup leaks into a run.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from recap.env import Reset
from recap.llm import LLMError
from recap.runtime import Conversation, EnvDriver, Episode, EpisodeEnd

#: the package's SWE-bench configuration, relative to its ``config`` folder
SWEBENCH_CONFIG = "extra/swebench.yaml"
#: the configurations ``MiniSweConfig.package_config`` names: the installed package's, or 1.0.0's (shipped)
INSTALLED, RELEASED_VERSION = "installed", "1.0.0"
PACKAGE_CONFIGS = (INSTALLED, RELEASED_VERSION)
#: mini-swe-agent 1.0.0's configuration (README.md there: source, digests, licence)
RELEASED_DIR = Path(__file__).resolve().parent / "mini_swe_1_0_0"
#: the installed package's submit line (its swebench.yaml's; our environment's default)
INSTALLED_SENTINEL = "COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
#: the repository folder the package's SWE-bench task text names (its docker image's)
PACKAGE_WORKDIR = "/testbed"
#: the text layout the offline test doubles write (workers/llm/offline/expert_tools.py)
BASH_BLOCK = "bash_block"
#: message kinds: the two pins, then what each user message after a reply is
KIND_SYSTEM, KIND_TASK = "system", "task"
KIND_OBSERVATION, KIND_FORMAT_ERROR, KIND_TIMEOUT, KIND_EXIT = "observation", "format_error", "timeout", "exit"
#: the end reasons of our environment that are a submission (the package: ``Submitted``)
SUBMITTED_REASONS = ("success", "agent_done")


class PackageMissing(RuntimeError):
    """mini-SWE-agent is not installed (``pip install 'recap-eval[swe]'``)."""


@dataclass(frozen=True)
class Package:
    """What an episode uses of the package: its agent class, its two ending exceptions and its
    SWE-bench ``agent`` settings (templates, limits) as the YAML file has them."""

    agent_cls: type
    submitted: type[Exception]
    limits_exceeded: type[Exception]
    agent_settings: Mapping[str, Any]
    version: str
    #: whose configuration ``agent_settings`` is (:data:`PACKAGE_CONFIGS`)
    config: str = INSTALLED
    #: the first output line that submits (our environment is told it)
    submit_sentinel: str = INSTALLED_SENTINEL

    @property
    def step_limit_from_run(self) -> bool:
        """Whether the package's ``step_limit`` is the run's call cap (installed) or the
        configuration's own (1.0.0: 0, none)."""
        return self.config == INSTALLED


def released_settings() -> tuple[dict[str, Any], str]:
    """mini-swe-agent 1.0.0's SWE-bench ``agent`` settings (its swebench.yaml over the code
    defaults it relies on) and its submit line, from ``mini_swe_1_0_0/``."""
    defaults = yaml.safe_load((RELEASED_DIR / "agent_defaults.yaml").read_text(encoding="utf-8"))
    config = yaml.safe_load((RELEASED_DIR / "swebench.yaml").read_text(encoding="utf-8"))
    return {**defaults["agent"], **config["agent"]}, str(defaults["submit_sentinel"])


def load_package(config: str = INSTALLED) -> Package:
    """Import mini-SWE-agent quietly (see the module docstring) and read the SWE-bench settings
    ``config`` names (the installed package's, or 1.0.0's)."""
    if config not in PACKAGE_CONFIGS:
        raise ValueError(f"package_config must be one of {', '.join(PACKAGE_CONFIGS)}, got {config!r}")
    os.environ.setdefault("MSWEA_SILENT_STARTUP", "1")
    os.environ.setdefault("MSWEA_GLOBAL_CONFIG_DIR", str(Path(tempfile.gettempdir()) / "recap-eval-mini-swe-agent"))
    try:
        import minisweagent
        from minisweagent.agents.default import DefaultAgent, LimitsExceeded, Submitted
        from minisweagent.config import builtin_config_dir
    except ImportError as exc:
        raise PackageMissing(f"the mini_swe method needs mini-SWE-agent: pip install 'recap-eval[swe]' ({exc})") from None
    version = str(minisweagent.__version__)
    if config == RELEASED_VERSION:
        settings, sentinel = released_settings()
        return Package(_as_1_0_0(DefaultAgent), Submitted, LimitsExceeded, settings, version, config, sentinel)
    installed = yaml.safe_load((Path(builtin_config_dir) / SWEBENCH_CONFIG).read_text())
    return Package(DefaultAgent, Submitted, LimitsExceeded, dict(installed["agent"]), version)


def _as_1_0_0(agent_cls: type) -> type:
    """The installed ``DefaultAgent`` where 1.0.0's differs in what reaches the model:

    * no submit check of its own: our environment submits on 1.0.0's line (and raises
      ``Submitted`` through :meth:`SandboxEnvironment.execute`); the installed check would also
      accept lines 1.0.0 did not;
    * templates rendered as 1.0.0 rendered them (``microsweagent/agents/default.py:63-65``, system text added as written at ``:73``): an
      undefined name is empty rather than an error, the system text is sent as written (1.0.0 did
      not render it; rendering drops its final newline)."""
    from jinja2 import Template

    class ReleasedConfigAgent(agent_cls):
        def has_finished(self, output: dict[str, str]) -> None:
            return None

        def render_template(self, template: str, **kwargs: Any) -> str:
            if template is self.config.system_template:
                return template
            names = dataclasses.asdict(self.config) | self.env.get_template_vars() | self.model.get_template_vars()
            return Template(template).render(**kwargs, **names, **getattr(self, "extra_template_vars", {}))

    return ReleasedConfigAgent


def command_output(observation: str, exit_code: int | None) -> str:
    """A command's output as the package's templates expect it: our environment's observation
    without the two markers its templates already say otherwise (``[no output]`` for an empty
    output, ``[exit code N]``: the template shows ``<returncode>``). Cut and timeout notes stay."""
    if observation == "[no output]":
        return ""
    if exit_code not in (0, None):
        marker = f"[exit code {exit_code}]"
        if observation == marker:
            return ""
        if observation.endswith("\n" + marker):
            return observation[: -len(marker) - 1]
    return observation


@dataclass(frozen=True)
class SandboxEnvironmentConfig:
    """What the package's templates may read of the environment: the folder commands run in and
    one command's time limit."""

    cwd: str
    timeout: float


class SandboxEnvironment:
    """The package's ``Environment`` on our environment driver (see the module docstring)."""

    def __init__(self, driver: EnvDriver, package: Package, *, cwd: str, timeout: float) -> None:
        self.driver = driver
        self.package = package
        self.config = SandboxEnvironmentConfig(cwd=cwd, timeout=timeout)
        #: how our environment ended the episode (None while it goes on)
        self.end: EpisodeEnd | None = None
        #: the kind of the user message the package adds next (None: no command ran since the
        #: last query, so that message is a format error)
        self.pending: str | None = None
        self.commands: list[str] = []

    def execute(self, command: str, cwd: str = "") -> dict[str, Any]:
        """Run ``command`` as one step of our environment (always in its working folder: the
        package's ``DefaultAgent`` passes no ``cwd``). Its return code and output; a command our
        sandbox stopped at its time limit raises ``subprocess.TimeoutExpired`` (the package
        answers with its timeout template); our environment's end raises the package's
        ``Submitted`` (a submission) or ``LimitsExceeded`` (a limit)."""
        self.commands.append(command)
        try:
            step = self.driver.execute(command)
        except EpisodeEnd as end:
            self.end = end
            if end.reason in SUBMITTED_REASONS:
                raise self.package.submitted(self.driver.observation) from None
            raise self.package.limits_exceeded(self.driver.observation) from None
        code = step.info.get("exit_code")
        returncode = code if isinstance(code, int) else None
        output = command_output(step.observation, returncode)
        if step.info.get("timed_out"):
            self.pending = KIND_TIMEOUT
            raise subprocess.TimeoutExpired(command, self.config.timeout, output=output.encode("utf-8"))
        self.pending = KIND_OBSERVATION
        return {"output": output, "returncode": returncode}

    def get_template_vars(self) -> dict[str, Any]:
        """The config's fields (the package's own environments give theirs)."""
        return dataclasses.asdict(self.config)


@dataclass(frozen=True)
class GatewayModelConfig:
    """What the package's templates may read of the model: its name as the run labels it."""

    model_name: str = "gateway"


class GatewayModel:
    """The package's ``Model`` on the episode's conversation (see the module docstring)."""

    def __init__(
        self, conv: Conversation, env: SandboxEnvironment, hints: Mapping[str, Any], model_name: str = "gateway"
    ) -> None:
        self.conv = conv
        self.env = env
        self.hints = dict(hints)
        self.config = GatewayModelConfig(model_name=model_name)
        self.n_calls = 0
        self._mirrored = 0
        self._purpose = KIND_TASK

    @property
    def cost(self) -> float:
        """USD spent by the episode so far (the package's ``cost_limit`` reads it)."""
        return self.conv.usage.cost_usd

    def query(self, messages: list[dict[str, str]], **kwargs: Any) -> dict[str, Any]:
        """One model call on exactly ``messages`` (mirrored into our history first)."""
        self.mirror(messages)
        self.n_calls += 1
        raw, _ = self.conv.ask(None, self._purpose, _keep, context=self.hints, decode=_raw_text)
        return {"content": raw["text"]}

    def mirror(self, messages: Sequence[Mapping[str, Any]], *, closing: bool = False) -> None:
        """Add the package's messages we have not seen to our history, with their kinds (which
        emits their ``messages`` rows), and check the two are the same conversation; ``closing``:
        the last one is the package's closing message (the submission, a limit)."""
        history = self.conv.history
        for i in range(self._mirrored, len(messages)):
            role, content = str(messages[i]["role"]), str(messages[i]["content"])
            if i == 0:
                self.conv.pin_message(role, KIND_SYSTEM, content)
            elif i == 1:
                self.conv.pin_message(role, KIND_TASK, content)
            elif role == "assistant":
                pass  # our own reply, added by Conversation when it came back
            else:
                kind = KIND_EXIT if closing and i == len(messages) - 1 else self.env.pending or KIND_FORMAT_ERROR
                self.env.pending = None
                if kind == KIND_FORMAT_ERROR:
                    self.conv.usage.json_repairs += 1
                history.add(role, kind, content)
                self._purpose = kind
        self._mirrored = len(messages)
        ours = [(m.role, m.content) for m in history.messages()]
        theirs = [(str(m["role"]), str(m["content"])) for m in messages]
        if ours != theirs:
            raise RuntimeError(f"mini_swe: our history ({len(ours)} messages) is not the package's ({len(theirs)})")

    def get_template_vars(self) -> dict[str, Any]:
        """The config's fields and the call count and cost (as the package's own models give them)."""
        return dataclasses.asdict(self.config) | {"n_model_calls": self.n_calls, "model_cost": self.cost}


def _keep(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def _raw_text(text: str) -> dict[str, Any]:
    return {"text": text}


class WholeConversation(Conversation):
    """The episode's conversation with nothing ever dropped: the package sends its whole history
    and has no recovery from a context overflow, so one ends the episode (``llm_error``)."""

    def _end_on_error(self, exc: LLMError) -> None:
        if exc.kind == "context_length":
            raise EpisodeEnd("llm_error", f"context length exceeded (mini-SWE-agent drops nothing): {exc}", error_kind=exc.kind)
        super()._end_on_error(exc)


def whole_conversation(conv: Conversation) -> WholeConversation:
    """``conv`` as a :class:`WholeConversation`: the same history, usage, caps and records."""
    return WholeConversation(
        episode_id=conv.episode_id,
        client=conv.client,
        config=conv.config,
        style=conv.style,
        emit=conv.emit,
        expected_format=conv.expected_format,
        reply_fields=conv.reply_fields,
        usage=conv.usage,
        history=conv.history,
    )


def agent_settings(package: Package, *, workdir: str, step_limit: int, cost_limit: float) -> dict[str, Any]:
    """The package's SWE-bench ``agent`` settings for one episode: its templates as they are, but
    for the repository folder (ours instead of ``/testbed``), and the limits from the run's caps
    (``step_limit``: model calls, the package's unit; ``cost_limit``: USD, 0 for none)."""
    settings = dict(package.agent_settings)
    if workdir != PACKAGE_WORKDIR:
        settings["instance_template"] = settings["instance_template"].replace(PACKAGE_WORKDIR, workdir)
    settings["step_limit"] = step_limit
    settings["cost_limit"] = cost_limit
    return settings


def play_package(ep: Episode, reset: Reset, *, step_limit: int, cost_limit: float, package: Package | None = None) -> None:
    """One episode of the package's ``DefaultAgent.run`` (the task: the issue text, as its
    SWE-bench runner passes it); ends by an EpisodeEnd: our environment's, our caps', or the
    package's own limit (``call_cap`` for ``step_limit``, ``episode_limit`` for ``cost_limit``)."""
    pkg = package if package is not None else load_package()
    if not pkg.step_limit_from_run:
        step_limit = int(pkg.agent_settings["step_limit"])
    if len(ep.conv.history):
        raise EpisodeEnd("env_error", "mini_swe pins its own prompts: this episode already has a demonstration or release prompt")
    ep.conv = conv = whole_conversation(ep.conv)
    workdir = str(getattr(ep.env, "workdir", PACKAGE_WORKDIR))
    limits = getattr(ep.env, "limits", None)
    timeout = float(getattr(limits, "command_timeout_s", 60.0))
    if hasattr(ep.env, "submit_sentinel"):
        ep.env.submit_sentinel = pkg.submit_sentinel  # the line the configuration tells the model to print
    elif pkg.submit_sentinel != INSTALLED_SENTINEL:
        raise EpisodeEnd("env_error", f"mini_swe {pkg.config}: this environment cannot submit on {pkg.submit_sentinel}")
    env = SandboxEnvironment(ep.driver, pkg, cwd=workdir, timeout=timeout)
    hints = {"task": reset.goal, "depth": 0, "valid_actions": None, "text_layout": BASH_BLOCK}
    if pkg.submit_sentinel != INSTALLED_SENTINEL:  # the offline test doubles submit with the configuration's line
        hints["submit_sentinel"] = pkg.submit_sentinel
    model = GatewayModel(conv, env, hints)
    agent = pkg.agent_cls(model, env, **agent_settings(pkg, workdir=workdir, step_limit=step_limit, cost_limit=cost_limit))
    status, _ = agent.run(reset.observation)
    model.mirror(agent.messages, closing=True)  # the package's closing message (the submission, a limit)
    if env.end is not None:
        raise env.end
    if status == "LimitsExceeded" and 0 < step_limit <= model.n_calls:
        raise EpisodeEnd("call_cap", f"{model.n_calls} model calls (mini-SWE-agent's step_limit {step_limit})")
    if status == "LimitsExceeded":
        raise EpisodeEnd("episode_limit", f"${model.cost:.4f} spent (mini-SWE-agent's cost_limit ${cost_limit:g})")
    raise EpisodeEnd("agent_done", f"mini-SWE-agent ended with {status}")
