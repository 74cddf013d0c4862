"""ReCAP in tool-call mode: the loop the paper runs on SWE-bench, for environments with tools.

The release (swebench-recap/sweagent/agent/agents.py, ``forward`` :1071-1157) moves one node
pointer through the task tree, one model reply at a time. Each reply is a JSON ``{"think",
"subtasks"}`` text (which, when present, becomes the node's new version, :1108-1110) plus any
tool calls; what comes next depends on the reply, tool calls first (the paper: "we prioritize
tool execution over subtask decomposition"):

* tool calls: each is run (:meth:`recap.runtime.EnvDriver.execute_tool`) and answered in the
  history; the node stays current and the next prompt is the *action taken* prompt with the
  latest observation, the task and its list as proposed before (:1118-1129). As in the release
  (:750-753), that prompt *is* the tool message of the reply's (last) call, so the observation is
  not sent twice; the results of earlier calls of the same reply are their bare observations;
* else a non-empty list: its head becomes a child node and the next prompt is the *down*
  prompt (:1130-1137);
* else (an empty list): the node is done and the parent becomes current, with the *up* prompt
  re-injecting the parent's task, latest think and remaining subtasks (:1138-1150).

The root's parent is a pre-root node "review and submit" (agents.py:618-621; the appendix's
"SWE-bench Verified Experiment Details"), whose think says to check the issue is resolved and
then submit, with the one subtask ``submit``; an empty list at the pre-root ends the agent
(``agent_done``, :1141-1143). Where we differ: returning from the root shows the pre-root's list
as it stands (``submit``), since the root was not taken from it (the release shows the list
after its head, which is then empty); a reply that is neither usable JSON nor tool calls is
repaired (the runtime's JSON repair) where the release re-queries with its format-error
template; ``max_level`` (the depth ablations) asks a node at the cap to act or finish rather
than decompose (on entering it, and again if it decomposes all the same: its list is kept but
not descended into); no rule reminders (the release has none there). Under
``tool_calls_per_reply: one`` (``profile: released`` on SWE-bench) a reply with several calls is
re-asked, none of its calls run (:func:`recap.recap_tool_prompts.one_call_prompt`; the release's
parser, swebench-recap/sweagent/tools/parsing.py:439-449, requeries it); the re-ask stays in the
history, as our JSON repairs do, where the release's requery is temporary (agents.py:854-886).

Tree records: the pre-root is the tree's root node (depth 0, ``root``), the task's root its first
child (depth 1), as the release counts depth (:623). A node that called tools and has no
children is ``primitive`` (its ``step_index``: its first call's attempt); a tool-only reply
(no text) adds no version, as the release keeps the node's info then.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

from recap import recap_tool_prompts as TP
from recap.config import ReCAPConfig
from recap.env import Reset
from recap.jsonreply import parse_json_object, recap_reply
from recap.llm import ToolCall
from recap.runtime import Episode, EpisodeEnd
from recap.tree import Node


class TreeAgent(Protocol):
    """What the loop uses of :class:`recap.recap_agent.ReCAPAgent` (named here, not imported:
    the agent imports this module): its settings, its episode state and its node maker, so both
    modes keep one tree the same way."""

    config: ReCAPConfig

    def _state(self, ep: Episode) -> dict[str, Any]: ...

    def _new_node(self, ep: Episode, parent: Node | None, task: str) -> Node: ...


#: the tool-choice setting of every request (the release's function calling leaves it to the model)
TOOL_CHOICE = "auto"


def _decode(text: str) -> dict[str, Any]:
    """The reply text's JSON object under ``"text"`` (a tool-only reply decodes to ``{}``)."""
    return {"text": parse_json_object(text)}


def _parser(with_think: bool) -> Callable[[dict[str, Any]], dict[str, Any]]:
    def parse(obj: dict[str, Any]) -> dict[str, Any]:
        if "text" not in obj:  # tool calls and no text
            return {"think": None, "subtasks": None}
        return recap_reply(obj["text"], with_think=with_think)

    return parse


def play_tools(agent: TreeAgent, ep: Episode, reset: Reset) -> None:
    """One ReCAP episode on an environment with tools (see the module docstring); returns when
    the agent finishes at the pre-root, else an EpisodeEnd (success on the final submit) ends it."""
    cfg, st = agent.config, agent._state(ep)
    st.update(nodes=[], max_depth=0)
    with_think = cfg.think != "none"
    tools = ep.env.tool_defs()
    parse = _parser(with_think)
    #: ``tool_calls_per_reply: one``: a reply with several calls is re-asked (the release's parser)
    one_call = TP.one_call_prompt if cfg.tool_calls_per_reply == "one" else None
    #: ``reply_schema``: the reply text under a strict JSON schema where the provider has one
    schema = TP.reply_schema(with_think) if cfg.reply_schema else None
    pre = agent._new_node(ep, None, TP.PRE_ROOT_TASK)
    pre.kind = "root"
    pre.add_version(TP.pre_root_think(reset.observation), (TP.SUBMIT_SUBTASK,), None, None)
    root = agent._new_node(ep, pre, reset.goal)
    ep.conv.pin(
        "task", TP.task_prompt(rules=ep.env.rules(), observation=reset.observation, goal=reset.goal, with_think=with_think)
    )
    #: nodes that called tools (primitive unless they also got children; kept for finish_kinds)
    acted: set[int] = st.setdefault("acted", set())
    node, prompt, kind = root, None, "task"
    shown: tuple[str, ...] = ()  # the remaining subtasks the current prompt showed (the expert's hint)
    while True:
        context = {
            "task": node.task,
            "depth": node.depth,
            "is_root": node is root,
            "is_pre_root": node is pre,
            "remaining": list(shown),
            "valid_actions": None,
        }
        reply, calls, seq = ep.conv.ask_tools(
            prompt,
            kind,
            parse,
            tools=tools,
            tool_choice=TOOL_CHOICE,
            node_id=node.node_id,
            context=context,
            decode=_decode,
            one_call=one_call,
            schema=schema,
        )
        if reply["subtasks"] is not None:
            node.add_version(reply["think"], reply["subtasks"], ep.conv.usage.calls - 1, seq)
        if calls:
            if node.step_index is None:
                node.step_index = ep.driver.attempts
            acted.add(node.node_id)
            try:
                _run_calls(ep, node, calls, seq)
            except EpisodeEnd as end:
                if end.reason == "success":  # the final submit: the node's work is done
                    node.status = "done"
                raise
            prompt, kind, shown = None, "action_taken", node.subtasks
            continue
        subtasks = reply["subtasks"] or ()
        if subtasks:
            if cfg.max_level is not None and node.depth >= cfg.max_level:
                prompt, kind, shown = TP.depth_cap_prompt(node.task), "depth_cap", ()
                continue
            node = agent._new_node(ep, node, subtasks[0])
            if cfg.max_level is not None and node.depth >= cfg.max_level:
                prompt, kind = TP.depth_cap_prompt(node.task), "depth_cap"
            else:
                prompt, kind = TP.down_prompt(node.task), "descend"
            shown = ()
            continue
        node.status = "done"
        _set_kind(node, acted)
        parent = node.parent
        if parent is None:
            return  # the pre-root is done: the agent ends (agents.py:1141-1143)
        # the head of the parent's list was this node, except at the pre-root (the root is not on its list)
        remaining = parent.subtasks if parent is pre and node is root else parent.subtasks[1:]
        prompt = TP.up_prompt(
            done_task=node.task,
            task=parent.task,
            thinks=parent.thinks,
            subtasks=remaining,
            think_mode=cfg.think,
            name_only=cfg.name_only,
        )
        node, kind, shown = parent, "return", tuple(remaining)


def _run_calls(ep: Episode, node: Node, calls: tuple[ToolCall, ...], seq: int) -> None:
    """Run a reply's calls in order; the last one's tool message is the action-taken prompt."""
    for i, call in enumerate(calls):
        step = ep.driver.execute_tool(call, node.node_id, seq)
        if i < len(calls) - 1:
            ep.conv.add_tool_result(call, step.observation, node.node_id)
        else:
            text = TP.action_taken_prompt(observation=step.observation, task=node.task, subtasks=node.subtasks)
            ep.conv.add_tool_result(call, text, node.node_id)


def _set_kind(node: Node, acted: set[int]) -> None:
    """A finished node's kind: ``primitive`` when it only acted, ``composite`` when it has children."""
    if node.kind == "root":
        return
    node.kind = "primitive" if node.node_id in acted and node.n_children == 0 else "composite"
    if node.kind == "composite":
        node.step_index = None  # as in text mode: only an acting leaf names its step


def finish_kinds(st: dict[str, Any]) -> None:
    """Every node's kind at the end of a tool-mode episode (nodes still open included), by the
    same rule as a finished node's."""
    acted = st.get("acted", set())
    for node in st.get("nodes", []):
        _set_kind(node, acted)
