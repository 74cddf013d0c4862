"""How the methods run on FEVER: what the ``paper`` and ``released`` profiles mean here, which
method the paper did not run, and which methods give only a verdict, declared by the benchmark
(recap.config.BenchmarkProtocol).

Read from GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f (``fever-recap``) and the paper's appendix
"FEVER Experiment Details":

* the cap: 10 actions for every method (the paper; ``conf/config.toml:3`` ``max_retry = 10`` and
  the notebooks' ``for i in range(1, 11)``, React.ipynb / baseline_act.ipynb cell 4:24). The environment
  enforces it (``workers/envs/fever/env.py``: ``max_steps`` 10). ReCAP under ``released`` is the
  exception: ``max_retry`` reaches hotpotqa_simulator.py as ``max_steps`` but nothing counts
  against it (below), so the environment gets the safety bound instead (:func:`env_options`);
* ``paper``: the Robotouille hyperparameters (temperature 0.5, no output cap) for every method,
  which is the generic profile; an episode of 10 actions never reaches its window;
* ``released``: no temperature in any released FEVER call (ReCAP: MATRIX/MATRIX/chatbot.py:49
  commented out; React.ipynb and baseline_act.ipynb: the ``llm`` helper's temperature commented
  out; baseline_cot.ipynb / baseline_standard.ipynb: none passed). ReCAP runs as
  ``main.py`` -> ``hotpotqa/hotpotqa_simulator.py`` -> ``MATRIX/MATRIX/chatbot.py`` ran it
  (:data:`RECAP_RELEASED`): no step cap (hotpotqa_simulator.py:22 sets ``steps = 0`` and :33's
  ``steps < max_steps`` never sees it grow), so a stated safety bound of :data:`SAFETY_STEPS`
  actions replaces the paper's 10 and an episode it ends says so in its row; a one-item list
  reaches Wikipedia only when it matches :data:`RELEASED_ACTION` (chatbot.py:308-312, 379-381),
  anything else gets the fail prompt and uses no step (:412-423); when the root's list empties
  the final-answer prompt is sent and its first subtask is the last action (:470-478); the rules
  go before the prompt of every 10th call (:350-360: ``invoke_cnt`` counts every call of the loop;
  this module's docstring used to say the release sends no reminder, which the code contradicts);
  past 32 messages ``history[1:3]`` is deleted before the prompt goes in (:42-44; ``window_mode:
  prompt``, two messages and only then, so a call may see 33 after an odd error message), so the
  demonstration (history[0], :76, 330) stays and the task prompt goes first (32 dropped on a
  context-length error, :59-62); all of a node's thoughts are re-injected, numbered from 1
  (``get_latest_think``, :122-126, used at :402, 410, 421, 445, 452); the two characters
  backslash-n are deleted from every observation (hotpotqa_simulator.py:42); no shortcut (the
  check runs only on a reply, :379); a reply that is not JSON gets the release's error message
  and the same prompt again (:370-371, 461-469; no bound there, the call cap here). ReAct and
  Act resend the whole growing trajectory every call (React.ipynb cell 4: ``history`` grows by one user and one assistant
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
  release's text, which only ``prompts: release`` brings. ReCAP renders every prompt from the
  released loop's own templates (chatbot.py's ``Prompt`` methods, its demonstration frame,
  reminder, final-answer and error messages, conf/config.toml's rules), read by
  ``workers/release/fever_matrix.py``;
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
#: the safety bound on ReCAP's actions under ``released`` (the release has none:
#: hotpotqa_simulator.py:22,33); five times the paper's cap, so it binds only on a runaway episode
SAFETY_STEPS = 50
#: the released FEVER ReCAP's check of a one-item list (fever-recap/MATRIX/MATRIX/chatbot.py:310),
#: its verbs' first letter in either case: our rules spell the actions in lower case (rules.py) and
#: the runner lower-cases the first letter before stepping anyway (hotpotqa_simulator.py:41); the
#: released rules (conf/config.toml) ask for the capitalised form, which both accept
RELEASED_ACTION = r"^([Ss]earch|[Ll]ookup|[Ff]inish)\[.*\]$"
#: ReCAP under ``released`` on FEVER, each as fever-recap/ cites it (see the module docstring):
#: chatbot.py:42-44 (32 messages counting the demonstration; the task prompt windowed) and
#: :59-62; :350-360 (the rules before every 10th call's prompt); :122-126 (every thought,
#: numbered); :308-312, 412-423 (the pattern, no step on a miss); :470-478 (final answer);
#: :379 (no shortcut); hotpotqa_simulator.py:42 (backslash-n deleted), :22,33 (no step cap)
RECAP_RELEASED: dict[str, Any] = {
    "window": 32,
    "window_counts_pins": True,
    "window_mode": "prompt",
    "pin_task": False,
    "context_drop": 32,
    "reminder_period": 10,
    "reminder_on": "nth_call",
    "temperature": None,
    "think": "many",
    "shortcut": False,
    "shortcut_trace": False,
    "action_pattern": RELEASED_ACTION,
    "final_answer": True,
    "observation_drop": "\\n",
    "safety_steps": SAFETY_STEPS,
    "resend_bad_replies": True,
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
    """``prompts: release`` on FEVER: ReCAP's released prompts are the released templates
    (workers/release/fever_matrix.py) whatever the profile and imply no setting (the release does
    re-send its rules, chatbot.py:350-360, so the reminder stays the profile's); ReAct, Act, CoT and
    Standard run the notebooks' loops, which read plain-text replies and resend the whole history
    (:data:`NOTEBOOK_SETTINGS`, see the module docstring)."""
    if issubclass(config_cls, ReActConfig):
        return dict(NOTEBOOK_SETTINGS)
    if issubclass(config_cls, PlanConfig):
        return {k: v for k, v in NOTEBOOK_SETTINGS.items() if k != "history"}
    return {}


def env_options(config: AgentConfig | None) -> dict[str, Any]:
    """The environment options a method's settings ask for on FEVER: a ReCAP whose settings
    replace the step cap by a safety bound (``safety_steps``, the released profile) gets that
    many actions."""
    if isinstance(config, ReCAPConfig) and config.safety_steps is not None:
        return {"max_steps": config.safety_steps}
    return {}


def verdict_only(config: AgentConfig | None) -> bool:
    """Whether a method with settings ``config`` gives only the verdict (CoT, Standard: a plan
    written once, before any observation)."""
    return isinstance(config, PlanConfig)


def refusal(method: str) -> str | None:
    """Why ``method`` cannot run on FEVER, or None."""
    return REFUSED_METHODS.get(method)
