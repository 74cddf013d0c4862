"""ReAct as mini-SWE-agent runs it: the paper's ReAct baseline on SWE-bench ("we used
mini-SWE-agent ... as the ReAct baseline"), for ``react`` on an environment with tools.

Why ``react`` and not a method of its own: the paper reports mini-SWE-agent in its ReAct column,
so a sweep's ``react`` on ``swe`` is that baseline and reports compare the same method names
across benchmarks. The environment decides the loop (as ``reply_format: text`` does).

One episode (mini-SWE-agent's DefaultAgent with its SWE-bench configuration; prompts in
:mod:`recap.baselines.react_swe_prompts`):

* pinned: the task prompt (reply form, the environment's rules, the issue, the goal, how to work
  and submit). No tools are sent: the model acts by text only;
* each reply is plain text; the one ```bash block it holds is the action, run as one command by
  the environment's text action (``EnvDriver.execute`` -> ``Environment.step``); the next prompt
  is the command's return code and output;
* a reply with no or several bash blocks is answered with a format error and asked again; it
  counts as a JSON repair, and more than ``max_json_repairs`` in a row end the episode
  (``json_failures``; mini-SWE-agent itself only has its step and cost limits);
* the episode ends when the submit sentinel's command runs (the environment submits), or at a
  cap. ``json_mode`` is off for these requests whatever the config says (the replies are text).

Message kinds: ``task`` (pinned), ``observation``, ``format_error``. Hints for the offline test
doubles: ``text_layout: bash_block`` (the expert answers with the plan's bash equivalents).
"""

from __future__ import annotations

import re
from typing import Any

from recap.baselines import react_swe_prompts as S
from recap.baselines.react_text import raw_text
from recap.env import Reset
from recap.runtime import Episode, EpisodeEnd

#: the text layout the offline test doubles write (workers/llm/offline/expert_tools.py)
BASH_BLOCK = "bash_block"
#: mini-SWE-agent's action regex: a ```bash fence, a newline, the command, a newline, the closing fence
ACTION_RE = re.compile(r"```bash\s*\n(.*?)\n```", re.DOTALL)


def _keep(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def bash_blocks(text: str) -> list[str]:
    """The commands of a reply's ```bash blocks, stripped."""
    return [m.strip() for m in ACTION_RE.findall(text)]


def play_swe(ep: Episode, reset: Reset, max_repairs: int) -> None:
    """One mini-SWE-agent episode (see the module docstring; ``max_repairs``: format errors allowed
    in a row); ends by an EpisodeEnd."""
    d = ep.driver
    ep.conv.pin("task", S.task_prompt(rules=ep.env.rules(), issue=reset.observation, goal=reset.goal))
    context = {"task": reset.goal, "depth": 0, "valid_actions": None, "text_layout": BASH_BLOCK}
    prompt: str | None = None
    kind = "task"
    errors = 0  # format errors in a row
    while True:
        raw, _ = ep.conv.ask(prompt, kind, _keep, context=context, decode=raw_text)
        blocks = bash_blocks(raw["text"])
        if len(blocks) != 1:
            if errors >= max_repairs:
                raise EpisodeEnd("json_failures", f"{errors + 1} replies in a row without exactly one bash block")
            errors += 1
            ep.conv.usage.json_repairs += 1
            prompt, kind = S.format_error_prompt(len(blocks)), "format_error"
            continue
        errors = 0
        step = d.execute(blocks[0])
        code = step.info.get("exit_code")
        prompt, kind = S.observation_prompt(step.observation, code if isinstance(code, int) else None), "observation"
