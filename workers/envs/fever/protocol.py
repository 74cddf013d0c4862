"""How the methods run on FEVER: what the ``paper`` and ``released`` profiles mean here, which
method the paper did not run, and which methods give only a verdict, declared by the benchmark
(recap.config.BenchmarkProtocol).

Read from GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f (``fever-recap``) and the paper's appendix
"FEVER Experiment Details":

* the cap: 10 actions for every method (the paper; ``conf/config.toml:3`` ``max_retry = 10`` and
  the notebooks' ``for i in range(1, 11)``, React.ipynb / baseline_act.ipynb cell 4:24). The environment
  enforces it (``workers/envs/fever/env.py``: ``max_steps`` 10);
* ``paper``: the Robotouille hyperparameters (temperature 0.5, no output cap) for every method,
  which is the generic profile; an episode of 10 actions never reaches its window;
* ``released``: no temperature in any released FEVER call (ReCAP: MATRIX/MATRIX/chatbot.py:49
  commented out; React.ipynb and baseline_act.ipynb: the ``llm`` helper's temperature commented
  out; baseline_cot.ipynb / baseline_standard.ipynb: none passed); ReCAP's history is cut to 32
  messages counted with the system prompt, the oldest pair after it dropped
  (chatbot.py:42-44), 32 more on a context-length error (chatbot.py:59-62), and it sends no
  rules reminder (session/SessionManager.py has none); ReAct and Act resend the whole growing
  trajectory every call (React.ipynb cell 4: ``history`` grows by one user and one assistant
  message per round), so no window;
* ``prompts: release`` (with ``released``: the notebooks as the authors ran them): ReAct, Act,
  CoT and Standard run the notebooks' own loops (:mod:`recap.baselines.notebook_loop`) on the
  text ``workers/release/fever_notebooks.py`` reads from them at run time: ReAct/Act as
  React.ipynb / baseline_act.ipynb cell 4 (the demonstration ``fever.json`` ``webthink_simple3`` /
  ``webact_simple3`` as the first user message, ``Thought i:`` / ``Action i:`` turns, stop
  ``["\\nObservation i:"]``, one assistant message per round), CoT/Standard as
  baseline_cot.ipynb / baseline_standard.ipynb cell 2 (one user message, ``finish[<answer>]``).
  Plain-text replies (no JSON mode) and the whole history are what those loops need, so
  ``prompts: release`` sets them (:func:`release_prompt_settings`). Under ``released`` with our
  prompts, ReAct/Act/CoT/Standard keep our JSON replies: the notebooks' loops read the
  release's text, which only ``prompts: release`` brings;
* CoT and Standard give the verdict only (the paper: "for Standard/CoT we prompt only the final
  verdict"; baseline_cot.ipynb / baseline_standard.ipynb step ``finish[<answer>]`` once): their
  environments are made with ``verdict_only`` (the rules then ask for a one-action plan);
* ADaPT: the paper's Table 1 has "--" for FEVER and the release has no FEVER ADaPT, so a sweep
  asking for it is refused before anything runs.
"""

from __future__ import annotations

from typing import Any

from recap.baselines.cot import PlanConfig
from recap.baselines.react import ReActConfig
from recap.baselines.reply_format import RELEASED_TEXT
from recap.config import AgentConfig, ReCAPConfig

#: the paper's FEVER cap: actions per episode, every method
MAX_ACTIONS = 10
#: fever-recap/MATRIX/MATRIX/chatbot.py:42-44 (history cut at 32 messages, system prompt
#: included) and :59-62 (32 dropped on a context-length error); no reminder (SessionManager.py)
RECAP_RELEASED: dict[str, Any] = {
    "window": 32,
    "window_counts_pins": True,
    "context_drop": 32,
    "reminder_period": None,
    "temperature": None,
}
#: React.ipynb / baseline_act.ipynb: the whole trajectory is resent on every call
REACT_RELEASED: dict[str, Any] = {"history": "all", "temperature": None}
#: the make() option that tells the environment the method gives a verdict only
VERDICT_ONLY = "verdict_only"
#: methods the paper did not run on FEVER, with the one-line reason a sweep is refused with
REFUSED_METHODS = {
    "adapt": "the paper reports no ADaPT result on FEVER (Table 1: --) and the release has no FEVER ADaPT",
}


def _without(settings: dict[str, Any], dropped: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in settings.items() if k not in dropped}


def profile_settings(config_cls: type[AgentConfig], profile: str, generic: dict[str, Any]) -> dict[str, Any]:
    """The profile's settings on FEVER for a method with config class ``config_cls``
    (:meth:`recap.config.BenchmarkProtocol.profile_settings`)."""
    out = dict(generic)
    if profile != "released":
        return out
    out["temperature"] = None
    if issubclass(config_cls, ReCAPConfig):
        out.update(RECAP_RELEASED)
    if issubclass(config_cls, ReActConfig):  # Act too (ActConfig subclasses it)
        out = _without(out, RELEASED_TEXT)
        out.update(REACT_RELEASED)
    if issubclass(config_cls, PlanConfig):
        out = _without(out, RELEASED_TEXT)  # the released answer line is our verdict-only JSON plan
    return out


#: what the notebooks' loops need under ``prompts: release`` (plain text, the whole history)
NOTEBOOK_SETTINGS: dict[str, Any] = {**RELEASED_TEXT, "history": "all"}


def release_prompt_settings(config_cls: type[AgentConfig]) -> dict[str, Any]:
    """``prompts: release`` on FEVER: ReCAP's released rules imply no reminder (the release sends
    none); ReAct, Act, CoT and Standard run the notebooks' loops, which read plain-text replies
    and resend the whole history (:data:`NOTEBOOK_SETTINGS`, see the module docstring)."""
    if issubclass(config_cls, ReCAPConfig):
        return {"reminder_period": None}
    if issubclass(config_cls, ReActConfig):
        return dict(NOTEBOOK_SETTINGS)
    if issubclass(config_cls, PlanConfig):
        return {k: v for k, v in NOTEBOOK_SETTINGS.items() if k != "history"}
    return {}


def verdict_only(config: AgentConfig | None) -> bool:
    """Whether a method with settings ``config`` gives only the verdict (CoT, Standard: a plan
    written once, before any observation)."""
    return isinstance(config, PlanConfig)


def refusal(method: str) -> str | None:
    """Why ``method`` cannot run on FEVER, or None."""
    return REFUSED_METHODS.get(method)
