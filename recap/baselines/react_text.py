"""ReAct and Act under ``reply_format: text``: the released baselines' loop around plain-text replies.

What differs from the JSON loop in :mod:`recap.baselines.react` (citations: GitHub
``ReCAP-Stanford/ReCAP`` at 2fb112f):

* replies are read by :mod:`recap.baselines.textreply`, never repaired: a malformed reply (no
  ``Reasoning:`` / ``Action:`` line) is answered like an invalid action, with error feedback
  before the unchanged observation, and counts towards the same run of consecutive failures
  (``robotouille-baselines/agents/ReAct_agent.py:229-289``: five in a row make a round, the
  third round ends the episode; the rounds are ``invalid_streak`` / ``invalid_rounds``);
* the labelled layouts match the action to the valid actions ignoring case and punctuation,
  by containment, first match (ReAct_agent.py:291-308); ``Finish`` ends the episode
  (ReAct_agent.py:272-274);
* ALFWorld's one-line layout (``text_layout: yao``; alfworld-recap/react_alfworld/react.py):
  a ``think:`` line is answered "OK." and takes no step (react.py:159-160); any other line goes
  to the game as it is. What follows a command is the JSON loop's, from the same code: the game's
  observation as the environment writes it (listing the valid actions where the profile's
  ``valid_actions`` says so, react.py:172, 209) and, after a command that is not among them
  with ``invalid_feedback: explained``, :meth:`recap.baselines.react.ReActAgent.explained_feedback`
  (react.py:161-170).

The history and its window are the agent's (``history``, ``window``), as in the JSON loop.
Message kinds: ``task`` (pinned), ``observation``, ``feedback`` and, for a thought, ``thought``.
"""

from __future__ import annotations

from typing import Any

from recap.baselines import prompts as P
from recap.baselines import text_prompts as T
from recap.baselines.textreply import (
    TextReply,
    match_action,
    parse_reasoning_action,
    parse_think_or_action,
    render,
)
from recap.env import InvalidActionError, Reset
from recap.runtime import Episode, EpisodeEnd


def raw_text(text: str) -> dict[str, Any]:
    """``Conversation.ask``'s decode for plain-text replies: the text, unparsed."""
    return {"text": text}


def _keep(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def layout_of(agent: Any) -> str:
    """The reply layout: ALFWorld's one line (``yao``) or the labelled lines, with or without
    the reasoning."""
    if agent.config.text_layout == "yao":
        return "think_or_action"
    return "reasoning_action" if agent.with_think else "action"


def demo_texts(agent: Any, replies: list[dict[str, Any]]) -> list[str]:
    """Demonstration replies in the text layout: in the one-line layout each step's thought is a
    ``think:`` line of its own before the command (Act: the commands alone)."""
    layout = layout_of(agent)
    out: list[str] = []
    for r in replies:
        if layout == "think_or_action" and agent.with_think and r.get("think"):
            out.append(render(layout, {"think": r["think"]}))
        out.append(render(layout, r))
    return out


def _parse(layout: str, text: str, with_think: bool) -> TextReply:
    if layout == "think_or_action":
        return parse_think_or_action(text)
    return parse_reasoning_action(text, with_think=with_think)


def play_text(agent: Any, ep: Episode, reset: Reset) -> None:
    """One ReAct/Act episode with plain-text replies (see the module docstring)."""
    cfg, d = agent.config, ep.driver
    layout = layout_of(agent)
    yao = layout == "think_or_action"
    _pin_task(agent, ep, reset, yao)
    prompt: str | None = None
    kind = "task"
    streak = rounds = 0
    while True:
        valid = d.valid_actions
        context = {
            "task": reset.goal,
            "depth": 0,
            "valid_actions": list(valid) if valid is not None else None,
            "text_layout": layout,
        }
        raw, _ = ep.conv.ask(prompt, kind, _keep, context=context, decode=raw_text)
        reply = _parse(layout, raw["text"], agent.with_think)
        feedback: str | None = reply.error
        if reply.error is None and reply.action is None:  # a thought (one-line layout)
            prompt, kind = P.THOUGHT_ACK, "thought"
            continue
        if feedback is None and reply.finish and not yao:
            raise EpisodeEnd("agent_done", "the agent replied Finish")
        if feedback is None:
            assert reply.action is not None
            after = _take_action(agent, ep, reply.action, valid, yao)
            if after is not None:
                prompt, kind = after
                if kind == "observation":  # an action the game took; explained feedback keeps the run
                    streak = 0
                continue
            feedback = T.invalid_action(reply.action)
        prompt, kind = T.turn(d.observation, feedback=feedback), "feedback"
        streak, rounds = _count_unusable(cfg, streak, rounds)


def _pin_task(agent: Any, ep: Episode, reset: Reset, yao: bool) -> None:
    """Pin the task prompt: the system text of the layout, the rules and the first observation."""
    if yao:
        system = T.yao_system()
        # the goal only where the observation does not already state it (ALFWorld's "Your task
        # is to: ..." does; the release sends the observation alone, react.py:209)
        goal = "" if reset.goal in reset.observation else f"\n\nGoal: {reset.goal}"
        first = f"{reset.observation}{goal}"
    else:
        system = T.react_system(agent.with_think)
        first = T.turn(reset.observation, goal=reset.goal)
    # prompts: release: the authors' system text and instructions are pinned already
    # (recap.release_prompt); the first turn is the observation alone, as the release sends it
    # (ReAct_agent.py:232-241 prompts with the environment's observation text)
    preamble = not agent.demo_mode and "release" not in ep.extra
    if yao and "release" in ep.extra:  # ALFWorld: the released first prompt (react.py:132-142, 209)
        ep.conv.pin("task", T.release_alfworld_task(first))
    else:
        ep.conv.pin("task", T.task_prompt(system=system, rules=ep.env.rules(), body=first, preamble=preamble))


def _take_action(agent: Any, ep: Episode, said: str, valid: tuple[str, ...] | None, yao: bool) -> tuple[str, str] | None:
    """Send the reply's action to the game: (prompt, kind) to answer with, or None when the
    environment rejected it (the caller answers with error feedback)."""
    d = ep.driver
    action = said
    if not yao and valid is not None:
        action = match_action(said, valid) or said
    listed_valid = d.is_valid(action)
    try:
        d.execute(action)
    except InvalidActionError:
        return None
    if yao and not listed_valid and agent.config.invalid_feedback == "explained":
        return agent.explained_feedback(ep, action), "feedback"
    return (d.observation if yao else T.turn(d.observation)), "observation"


def _count_unusable(cfg: Any, streak: int, rounds: int) -> tuple[int, int]:
    """(streak, rounds) after one more unusable reply; ends the episode after ``invalid_rounds``
    rounds of ``invalid_streak`` in a row."""
    streak += 1
    if cfg.invalid_streak is not None and streak >= cfg.invalid_streak:
        streak, rounds = 0, rounds + 1
        if rounds >= cfg.invalid_rounds:
            raise EpisodeEnd("agent_done", f"{rounds} rounds of {cfg.invalid_streak} consecutive unusable replies")
    return streak, rounds
