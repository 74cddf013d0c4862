"""CoT and Standard under ``reply_format: text``: the released I/O agents' one plain-text plan,
checked whole before anything runs.

As in GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f, ``robotouille-baselines/agents/IO_agent.py``
(Standard) and ``IOCoT_agent.py`` (CoT):

* the plan is the lines after ``Plan:`` (Standard) or the ``Action:`` lines (CoT), read by
  :mod:`recap.baselines.textreply`; a reply with neither ends the episode, no re-ask
  (IO_agent.py:166-170);
* every planned action is matched, ignoring case and punctuation, to *exactly one* of the valid
  actions of the state the plan has reached, on a copy of the environment that steps through
  the plan (IO_agent.py:174-187); one action that matches none or several ends the episode
  before any action runs;
* the checked plan then runs; it running out before the goal ends the episode
  (IO_agent.py:150-153).

A copy that cannot be made (an environment holding an engine process) ends the episode with
``env_error``: the released check needs one. Message kinds: ``task`` (pinned) and the reply.
"""

from __future__ import annotations

from typing import Any

from recap.baselines import text_prompts as T
from recap.baselines.react_text import raw_text
from recap.baselines.textreply import parse_action_lines, parse_plan, render, unique_match
from recap.env import EnvError, Environment, InvalidActionError, Reset, agent_action
from recap.runtime import Episode, EpisodeEnd


def layout_of(agent: Any) -> str:
    """CoT: ``Action:`` lines; Standard: a ``Plan:`` block."""
    return "action_lines" if agent.with_think else "plan"


def demo_texts(agent: Any, replies: list[dict[str, Any]]) -> list[str]:
    """The demonstration's one reply in the agent's layout."""
    return [render(layout_of(agent), r) for r in replies]


def check_plan(env: Environment, valid: tuple[str, ...] | None, actions: list[str]) -> tuple[list[str], str | None]:
    """The plan matched action by action on a copy of ``env`` (whose valid actions now are
    ``valid``): (the matched valid actions, None) or (those matched so far, why the plan fails).
    Every action is checked, also those after the copy reaches the goal: the release's engine copy
    goes on stepping (IO_agent.py:176-187 loops over the whole plan), so a plan that reaches the
    goal and then names an action that matches nothing is refused whole
    (:meth:`recap.env.Environment.plan_copy` is the copy that goes on)."""
    try:
        sim = env.plan_copy()
    except Exception as exc:  # noqa: BLE001  (any engine that cannot be copied)
        raise EpisodeEnd("env_error", f"the plan cannot be checked on a copy of the environment: {exc}") from exc
    matched: list[str] = []
    for i, action in enumerate(actions, 1):
        hit = unique_match(action, valid) if valid is not None else agent_action(sim, action)
        if hit is None:
            return matched, f"planned action {i} of {len(actions)} ({action!r}) does not match exactly one valid action"
        matched.append(hit)
        try:
            step = sim.step(hit)
        except InvalidActionError:
            return matched, f"planned action {i} of {len(actions)} ({action!r}) is not valid"
        except EnvError as exc:
            raise EpisodeEnd("env_error", f"the plan cannot be checked past action {i} on the copy: {exc}") from exc
        valid = step.valid_actions
    return matched, None


def play_text(agent: Any, ep: Episode, reset: Reset) -> None:
    """One CoT/Standard episode with a plain-text plan (see the module docstring)."""
    layout = layout_of(agent)
    body = T.turn(reset.observation, goal=reset.goal)
    # prompts: release: the authors' system text, instructions and examples are pinned already
    # (recap.release_prompt); the first turn is the observation alone (IO_agent.py:155 prompts with it)
    preamble = not agent.demo_mode and "release" not in ep.extra
    ep.conv.pin("task", T.task_prompt(system=T.plan_system(agent.with_think), rules=ep.env.rules(), body=body, preamble=preamble))
    valid = ep.driver.valid_actions
    context = {"task": reset.goal, "depth": 0, "valid_actions": list(valid) if valid is not None else None, "text_layout": layout}
    raw, _ = ep.conv.ask(None, "task", lambda o: o, context=context, decode=raw_text)
    text = raw["text"]
    actions = parse_action_lines(text) if layout == "action_lines" else parse_plan(text)
    if not actions:
        label = "'Action:' line" if layout == "action_lines" else "'Plan:' line"
        raise EpisodeEnd("agent_done", f"the reply has no {label}; the plan is not run")
    matched, problem = check_plan(ep.env, valid, actions)
    if problem is not None:
        raise EpisodeEnd("agent_done", f"{problem}; no action was run")
    for action in matched:
        ep.driver.execute(action)
    raise EpisodeEnd("agent_done", f"the plan's {len(matched)} action(s) ran out before the goal was reached")
