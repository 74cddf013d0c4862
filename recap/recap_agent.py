"""ReCAP (Algorithm 1): plan-ahead decomposition over a recursive context tree, with structured
re-injection of the parent's think and remaining subtasks on every return, in one shared
sliding-window LLM context.

Control flow (see the paper, section 2, and docs/method.md):

* the root asks for a full subtask list for the goal;
* the head of a list becomes a child node. A child whose name is itself a valid action runs
  directly (the shortcut: no call). Otherwise the child is asked for its own list: exactly one
  item that is a valid action is executed (a leaf); exactly one item that is not a valid
  action is a leaf failure (no environment step); an empty list means nothing to do; longer
  lists make the child composite and it loops the same way;
* after each child, the parent is re-prompted with its latest think and remaining subtasks
  (plus the observation after an action) and returns a refined list; an empty list finishes
  the node, and at the root it ends the episode;
* the rules are re-sent every ``reminder_period`` LLM calls (``reminder_on: calls``, the paper)
  or control-loop iterations (``iterations``: every child entered, shortcuts included, and every
  return; the released code), prepended to whichever prompt is sent next; at ``max_level`` a
  node is asked for a single valid action instead of a decomposition;
* on an environment with tools (a coding benchmark) the episode runs in the paper's tool-call
  mode instead (:mod:`recap.recap_tools`);
* ``shortcut_trace`` (released code): a shortcut child still leaves its descend prompt and a
  synthetic reply naming the action in the history (no call is made);
* the released FEVER loop (``fever-recap/MATRIX/MATRIX/chatbot.py``, set by the FEVER protocol
  under ``profile: released``): a one-item list reaches the environment only when it matches
  ``action_pattern``, otherwise it is a leaf failure that uses no step (chatbot.py:308-312,
  379-381, 412-423), the root's own one-item list included (its ``during_down`` is true on the
  first call); when the root's list empties one more call asks for the final answer, whose
  first subtask is the last action (``final_answer``, chatbot.py:470-478; ``finish[]`` follows
  when that does not end the episode or the reply has no answer, hotpotqa_simulator.py:47-49);
  the task prompt is windowed (``pin_task: false``, chatbot.py:42-44); ``observation_drop`` is
  deleted from observations (hotpotqa_simulator.py:42); ``safety_steps`` replaces the missing
  step cap and an episode it (or the call cap derived from it) ends says so in its row.
  Under ``prompts: release`` every prompt is the released template (``ReleasePrompt.templates``).
"""

from __future__ import annotations

import dataclasses
import json
import re
from functools import partial
from typing import Any

from recap import recap_prompts as P
from recap.agent import Agent
from recap.config import ReCAPConfig
from recap.demo_script import DemoScript
from recap.env import InvalidActionError, Reset
from recap.jsonreply import ReplyFormatError, parse_json_object, recap_reply
from recap.recap_tools import finish_kinds, play_tools
from recap.release_prompt import ReleasePrompt
from recap.runtime import Episode, EpisodeEnd, repair_prompt
from recap.tree import Node


class ReCAPAgent(Agent):
    """ReCAP: recursive plan-ahead decomposition in one shared sliding-window context, re-injecting
    the parent's think and remaining subtasks on every return (see the module docstring for the
    control flow)."""

    style = "recap"
    config_cls = ReCAPConfig
    expected_format = P.reply_format(True)
    config: ReCAPConfig
    #: a descend and a return per action, plus room for leaf failures and decompositions
    calls_per_step = 3.0
    #: every call asks for a (refined) subtask list. Kept with the think under ``no_think``: the
    #: parser then ignores it, and the offline test doubles' replies stay what they always were
    reply_fields = ("think", "subtasks")
    #: about one call per step while plans hold, up to ~2.5 per allowed step when it re-plans
    estimate_calls_per_step = (1.0, 2.5)

    @classmethod
    def demo_replies(cls, script: DemoScript) -> list[dict[str, Any]]:
        """The script's decomposition, one ``{"think", "subtasks"}`` reply per call."""
        return [{"think": think, "subtasks": list(subtasks)} for think, subtasks in script.decomposition]

    def reply_format(self) -> str:
        return P.reply_format(self.config.think != "none")

    def demo_config(self) -> ReCAPConfig:
        """Demonstrations are written for the full method: no depth cap, shortcut on (the depth
        and shortcut ablations change how the agent runs, not the example it is shown)."""
        base = super().demo_config()
        assert isinstance(base, ReCAPConfig)
        # the released FEVER loop's checks and last call are not part of the example either
        return dataclasses.replace(
            base, max_level=None, shortcut=True, reminder_period=None, action_pattern=None, final_answer=False, safety_steps=None
        )

    def shape_demo_reply(self, reply: Any) -> Any:
        if self.config.think == "none":
            return {k: v for k, v in reply.items() if k != "think"}
        return reply

    # -- episode state kept on the Episode object (the agent object itself stays reusable) ----
    def _state(self, ep: Episode) -> dict[str, Any]:
        return ep.extra

    def play(self, ep: Episode, reset: Reset) -> None:
        if ep.env.tool_defs():  # a coding environment: the paper's tool-call mode (recap.recap_tools)
            ep.extra["tool_mode"] = True
            return play_tools(self, ep, reset)
        if self.config.safety_steps is None or self.demo_mode:
            return self._play(ep, reset)
        try:
            return self._play(ep, reset)
        except EpisodeEnd as end:
            if end.reason not in ("step_cap", "call_cap"):
                raise
            # the released code has no step cap (hotpotqa_simulator.py:22,33): this end is our bound
            raise EpisodeEnd(
                end.reason,
                f"safety bound ({end.detail}; safety_steps {self.config.safety_steps}, the released code has no cap)",
            ) from None

    def _play(self, ep: Episode, reset: Reset) -> None:
        cfg = self.config
        st = self._state(ep)
        st.update(nodes=[], iterations=0, rules=ep.env.rules(), max_depth=0, remind=False, next_reminder_call=cfg.reminder_period)
        with_think = cfg.think != "none"
        root = self._new_node(ep, None, reset.goal)
        root.kind = "root"
        release = st.get("release")
        if isinstance(release, ReleasePrompt) and release.first_turn == "templated":
            # the released FEVER code's own first prompt (fever-recap/MATRIX/MATRIX/chatbot.py:333-338):
            # the root's task is the first observation and the initial observation the runner's
            # text (hotpotqa_simulator.py:25-26)
            st["rules"] = release.rules or ""
            root.task = reset.observation
            task = release.render(
                "task",
                task_name=reset.observation,
                init_obs=release.first_observation or "",
                rule=st["rules"],
                system_prompt=release.system or "",
            )
        elif isinstance(release, ReleasePrompt) and release.system is not None and release.rules is not None:
            # prompts: release: the released template's system text and rules frame the first
            # prompt (robotouille-recap/MATRIX/MATRIX/chatbot.py:247-261) and its reminders
            st["rules"] = release.rules
            if release.first_turn == "framed":  # alfworld-recap/MATRIX/MATRIX/chatbot.py:242-253
                task = P.release_alfworld_task_prompt(
                    system=release.system, rules=release.rules, observation=reset.observation, goal=reset.goal
                )
            else:
                task = P.release_task_prompt(
                    system=release.system,
                    rules=release.rules,
                    observation=reset.observation,
                    goal=reset.goal,
                    ask_many=cfg.think == "latest" and not cfg.name_only and cfg.max_level is None,
                )
        else:
            task = P.task_prompt(
                rules=st["rules"],
                observation=reset.observation,
                goal=reset.goal,
                with_think=with_think,
                preamble=not self.demo_mode,
            )
        if cfg.pin_task:
            ep.conv.pin("task", task)
            self._ask(ep, root, None, "task")
        else:  # windowed: dropped first once the history is full (chatbot.py:42-44)
            self._ask(ep, root, task, "task")
        if cfg.action_pattern is not None and len(root.subtasks) == 1:
            # the released loop's first call is a descend too (chatbot.py:346, 379): a one-item
            # root list is the root's own action, after which the root is left (:392-394). A
            # non-matching one leaves the loop as well (the fail path reads the root's parent,
            # :414-421, and the error ends the loop): the final answer is asked for at once
            root.kind = "primitive"
            if self._matches(root.subtasks[0]):
                self._execute(ep, root, root.subtasks[0])
            else:
                self._fail(ep, root, root.subtasks[0])
        else:
            self._loop(ep, root)
        if cfg.final_answer:
            self._final_answer(ep, root)

    def _new_node(self, ep: Episode, parent: Node | None, task: str) -> Node:
        st = self._state(ep)
        depth = 0 if parent is None else parent.depth + 1
        node = Node(len(st["nodes"]), parent, depth, parent.n_children if parent else 0, task)
        if parent is not None:
            parent.n_children += 1
        st["nodes"].append(node)
        st["max_depth"] = max(st["max_depth"], depth)
        return node

    # -- rule reminders ------------------------------------------------------------------------
    def _tick_iteration(self, ep: Episode) -> None:
        """One control-loop iteration (a child entered or a return); arms the reminder when the
        period counts iterations."""
        cfg, st = self.config, self._state(ep)
        st["iterations"] += 1
        if cfg.reminder_on == "iterations" and cfg.reminder_period and st["iterations"] % cfg.reminder_period == 0:
            st["remind"] = True

    def _reminder_due(self, ep: Episode) -> bool:
        cfg, st = self.config, self._state(ep)
        if not cfg.reminder_period or self.demo_mode:
            return False
        if cfg.reminder_on == "nth_call":  # the call about to be made is number period, 2 x period, ...
            return (ep.conv.usage.calls + 1) % cfg.reminder_period == 0
        if cfg.reminder_on == "calls":
            # every reminder_period calls: the prompt of call period+1, 2*period+1, ... gets it
            due = st["next_reminder_call"] is not None and ep.conv.usage.calls >= st["next_reminder_call"]
            if due:
                while st["next_reminder_call"] <= ep.conv.usage.calls:
                    st["next_reminder_call"] += cfg.reminder_period
            return due
        due, st["remind"] = st["remind"], False
        return due

    def _with_reminder(self, ep: Episode, prompt: str) -> str:
        """``prompt`` with the rules reminder before it (the released template's where there is one)."""
        st = self._state(ep)
        release = st.get("release")
        if isinstance(release, ReleasePrompt) and release.first_turn == "templated":
            return release.render("reminder", rule=st["rules"]) + prompt  # fever chatbot.py:352-360
        if isinstance(release, ReleasePrompt) and release.rules is not None:
            return P.release_reminder(st["rules"]) + prompt
        return P.reminder(st["rules"]) + "\n\n" + prompt

    def _ask(self, ep: Episode, node: Node, prompt: str | None, kind: str, shown: tuple[str, ...] | None = None) -> None:
        if prompt is not None and self._reminder_due(ep):
            prompt = self._with_reminder(ep, prompt)
        parse = partial(recap_reply, with_think=self.config.think != "none")
        d = ep.driver
        context = {
            "task": node.task,
            "depth": node.depth,
            "is_root": node.parent is None,
            "remaining": list(shown if shown is not None else node.subtasks),
            "valid_actions": list(d.valid_actions) if d.valid_actions is not None else None,
        }
        if self.config.resend_bad_replies and prompt is not None:
            reply, seq = self._ask_resending(ep, node, prompt, kind, context)
        else:
            reply, seq = ep.conv.ask(prompt, kind, parse, node_id=node.node_id, context=context)
        node.add_version(reply["think"], reply["subtasks"], ep.conv.usage.calls - 1, seq)

    def _ask_resending(
        self, ep: Episode, node: Node, prompt: str, kind: str, context: dict[str, Any]
    ) -> tuple[dict[str, Any], int]:
        """The released FEVER loop's answer to a reply it cannot use (fever-recap/MATRIX/MATRIX/
        chatbot.py:370-371, 461-469): the reply is read as strict JSON once code fences are
        removed (:9, 12-18); one that is not gets the JSON error message, one without
        ``subtasks`` the error message naming the missing key, and the loop sends the same prompt
        again (a reminder due on that call goes before it too, :352-360), with no bound but the
        call cap. A reply the release would take but our parser refuses (a think that is not
        text, subtasks that are not a list of text) gets our repair message instead."""
        release = self._release_templates(ep)
        while True:
            raw, seq = ep.conv.ask(prompt, kind, _same, node_id=node.node_id, context=context, decode=_raw)
            try:
                obj = json.loads(_FENCE.sub("", raw["text"]))
            except ValueError:
                problem = release.render("json_error") if release is not None else P.bad_json_text()
            else:
                if isinstance(obj, dict) and "subtasks" not in obj:  # a KeyError in the release (:379)
                    problem = release.render("error", e="'subtasks'") if release is not None else P.reply_error_text("'subtasks'")
                else:
                    try:
                        return recap_reply(obj, with_think=self.config.think != "none"), seq
                    except ReplyFormatError as exc:
                        problem = repair_prompt(str(exc), self.reply_format())
            ep.conv.usage.json_repairs += 1
            ep.conv.history.add("user", "repair", problem, node.node_id)
            if self._reminder_due(ep):
                prompt = self._with_reminder(ep, prompt)

    # -- the recursive loop --------------------------------------------------------------------
    def _loop(self, ep: Episode, node: Node) -> None:
        while node.subtasks:
            child = self._new_node(ep, node, node.subtasks[0])
            outcome, failed_action = self._descend(ep, child)
            self._return(ep, node, child, outcome, failed_action)
        node.status = "done"

    def _descend(self, ep: Episode, child: Node) -> tuple[str, str | None]:
        cfg, d = self.config, ep.driver
        self._tick_iteration(ep)
        if cfg.shortcut and d.valid_actions is not None and d.is_valid(child.task):
            child.kind = "primitive"
            seq = self._shortcut_trace(ep, child) if cfg.shortcut_trace else None
            child.add_version(None, (child.task,), None, seq)
            return self._execute(ep, child, child.task)
        at_cap = cfg.max_level is not None and child.depth + 1 >= cfg.max_level
        if at_cap:
            self._ask(ep, child, P.depth_cap_prompt(child.task), "depth_cap")
        else:
            self._ask(ep, child, self._descend_prompt(ep, child.task), "descend")
        subtasks = child.subtasks
        if not subtasks:
            child.status = "done"
            return "nonleaf", None
        if at_cap or len(subtasks) == 1:
            child.kind = "primitive"
            action = subtasks[0]
            if self._matches(action) and d.is_valid(action):
                return self._execute(ep, child, action)
            return self._fail(ep, child, action)
        self._loop(ep, child)
        return "nonleaf", None

    def _matches(self, action: str) -> bool:
        """Whether a one-item list may reach the environment: ``action_pattern`` (stripped, as
        fever-recap/MATRIX/MATRIX/chatbot.py:308-312 checks it) when one is set."""
        pattern = self.config.action_pattern
        return pattern is None or re.match(pattern, action.strip()) is not None

    def _release_templates(self, ep: Episode) -> ReleasePrompt | None:
        release = self._state(ep).get("release")
        return release if isinstance(release, ReleasePrompt) and release.first_turn == "templated" else None

    def _descend_prompt(self, ep: Episode, task: str) -> str:
        release = self._release_templates(ep)
        return release.render("descend", task_name=task) if release is not None else P.descend_prompt(task)

    def _observation(self, ep: Episode) -> str:
        """The latest observation as prompts show it (``observation_drop`` deleted)."""
        drop, observation = self.config.observation_drop, ep.driver.observation
        release = self._release_templates(ep)
        if release is not None and release.first_observation is not None and ep.driver.steps == 0:
            observation = release.first_observation  # before any step (hotpotqa_simulator.py:26; chatbot.py:345)
        return observation.replace(drop, "") if drop else observation

    def _final_answer(self, ep: Episode, root: Node) -> None:
        """The released FEVER loop's last call (fever-recap/MATRIX/MATRIX/chatbot.py:470-478): ask
        for the final answer; the reply's first subtask is sent as the last action, unchecked
        (hotpotqa_simulator.py:34-41 steps whatever comes); a reply without one, or an action that
        does not end the episode, is followed by ``finish[]`` (hotpotqa_simulator.py:47-49). The
        reply is not repaired (the release gives up on one it cannot parse, :479-480)."""
        release = self._release_templates(ep)
        prompt = release.render("final_answer") if release is not None else P.final_answer_prompt()
        reply, seq = ep.conv.ask(prompt, "final_answer", _same, node_id=root.node_id, decode=_raw)
        answer = _first_subtask(reply["text"])
        node = self._new_node(ep, root, answer if answer is not None else "")
        node.kind = "primitive"
        node.add_version(None, (answer,) if answer is not None else (), ep.conv.usage.calls - 1, seq)
        if answer is not None:
            self._execute(ep, node, answer)
        self._execute(ep, node, "finish[]")

    def _shortcut_trace(self, ep: Episode, child: Node) -> int:
        """The released code's record of a shortcut: the descend prompt and a reply naming the
        action, added to the shared history without a call. Returns the reply's seq."""
        h = ep.conv.history
        prompt = P.descend_prompt(child.task)
        if self._reminder_due(ep):
            prompt = self._with_reminder(ep, prompt)
        h.add("user", "descend", prompt, child.node_id)
        reply = P.shortcut_reply(child.task, self.config.think != "none")
        return h.add("assistant", "shortcut", reply, child.node_id)

    def _execute(self, ep: Episode, child: Node, action: str) -> tuple[str, str | None]:
        child.step_index = ep.driver.attempts
        try:
            ep.driver.execute(action, child.node_id)
        except InvalidActionError:
            child.status = "failed"
            return "fail", action
        except EpisodeEnd:
            child.status = "done"  # the action ran; the episode ends after it
            raise
        child.status = "done"
        return "leaf", None

    def _fail(self, ep: Episode, child: Node, action: str) -> tuple[str, str | None]:
        child.step_index = ep.driver.attempts
        ep.driver.reject(action, child.node_id)
        child.status = "failed"
        return "fail", action

    def _return(self, ep: Episode, node: Node, child: Node, outcome: str, failed_action: str | None) -> None:
        cfg = self.config
        self._tick_iteration(ep)
        shown = node.subtasks if outcome == "fail" else node.subtasks[1:]
        release = self._release_templates(ep)
        if release is not None:
            kind, text = _release_return(release, outcome, child, node, shown, self._observation(ep), failed_action)
            self._ask(ep, node, text, kind, shown=tuple(shown))
            return
        kind, text = P.return_prompt(
            outcome=outcome,
            child_task=child.task,
            parent_task=node.task,
            thinks=node.thinks,
            subtasks=shown,
            observation=self._observation(ep) if outcome in ("leaf", "fail") else None,
            think_mode=cfg.think,
            name_only=cfg.name_only,
            failed_action=failed_action,
            hints=ep.env.failure_hints() if outcome == "fail" else "",
        )
        self._ask(ep, node, text, kind, shown=tuple(shown))

    # -- end of episode ------------------------------------------------------------------------
    def max_depth(self, ep: Episode) -> int:
        return int(self._state(ep).get("max_depth", 0))

    def finish(self, ep: Episode) -> None:
        if ep.extra.get("tool_mode"):
            finish_kinds(self._state(ep))
        for node in self._state(ep).get("nodes", []):
            ep.emit(node.record(ep.conv.episode_id))


#: a run of backticks, with the word json right after it: removed before a reply is read as JSON
#: under ``resend_bad_replies`` (fever-recap/MATRIX/MATRIX/chatbot.py:9, 12-18)
_FENCE = re.compile(r"`+(?:json)?", re.IGNORECASE)


def _same(obj: dict[str, Any]) -> dict[str, Any]:
    return obj


def _raw(text: str) -> dict[str, Any]:
    """The reply text as is (the final answer is read without repairs)."""
    return {"text": text}


def _first_subtask(text: str) -> str | None:
    """The first subtask of a final-answer reply, or None when it has none (not a JSON object,
    no list, an empty list, or a first item that is not text)."""
    try:
        obj = parse_json_object(text)
    except ReplyFormatError:
        return None
    subtasks = obj.get("subtasks")
    if not isinstance(subtasks, list) or not subtasks or not isinstance(subtasks[0], str) or not subtasks[0]:
        return None
    return subtasks[0]


def _release_return(
    release: ReleasePrompt, outcome: str, child: Node, node: Node, shown: tuple[str, ...], observation: str, failed: str | None
) -> tuple[str, str]:
    """The return prompt from the released FEVER templates (fever-recap/MATRIX/MATRIX/chatbot.py:
    leaf with subtasks left :398-404, leaf without :406-411, fail :417-423, non-leaf :442-453):
    the node's thoughts all numbered from 1 (``Node.get_latest_think``, :122-126, the last 100),
    its remaining subtasks one a line (the template's own text for none, :207-210, 288-291)."""
    thinks = node.thinks[-100:]
    values = {
        "obs": observation,
        "done_task_name": child.task,
        "fail_task_name": failed or child.task,
        "previous_stage_task_name": node.task,
        "previous_stage_think": "\n".join(f"{i}. {t}" for i, t in enumerate(thinks, 1)) if thinks else "None",
    }
    if outcome == "fail":
        kind = "leaf_fail"
    else:
        kind = ("leaf" if outcome == "leaf" else "nonleaf") + ("_done" if shown else "_judge")
    empty = dict(release.empty_list).get(kind, "")
    values["remaining_subtask_str"] = "\n".join(shown) if shown else empty
    return kind, release.render(kind, **values)
