"""ReCAP's tool-call mode (recap/recap_tools.py) on a toy coding environment, with a scripted model:
the exact messages of an episode, the tree it leaves, and the unhappy paths (broken arguments,
prose where JSON or a tool call was expected, several calls in one reply, the depth cap)."""

from __future__ import annotations

import json
from typing import Any

from recap import recap_tool_prompts as TP
from recap.config import ReCAPConfig
from recap.llm import LLMResponse, ToolCall
from recap.recap_agent import ReCAPAgent
from recap.runtime import NOT_RUN
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord, NodeRecord, ToolCallRecord
from tests.recap.toy_repo import TEST_CMD, TOOLS, ToyRepo

J = json.dumps
FIX = J({"path": "app.py", "old_str": "a - b", "new_str": "a + b"})
CHOICES = (
    "Now you may revise the subtasks in light of the latest observation, reply with an empty list "
    "if your current task is complete, break the first subtask down further by replying without a "
    "tool call, and/or call tools to make progress."
)
DOWN_CHOICES = (
    "Now you may break this task down if it is too large, reply with an empty list if it is "
    "already complete, go further down into its first subtask by replying without a tool call, "
    "and/or call tools to make progress."
)
PRE_THINK = "Check that the following issue is really resolved, then submit the change:\nadd(1, 2) returns -1 instead of 3."


def reply(text: str, *calls: tuple[str, str, str]) -> LLMResponse:
    return LLMResponse(text=text, model="scripted", tool_calls=tuple(ToolCall.parse(*c) for c in calls), test_double=True)


def plan(think: str, *subtasks: str) -> str:
    return J({"think": think, "subtasks": list(subtasks)})


def run(replies: list[Any], config: ReCAPConfig | None = None) -> tuple[Any, list[Any], ScriptedClient, ToyRepo]:
    rows: list[Any] = []
    env = ToyRepo()
    client = ScriptedClient(replies)
    result = ReCAPAgent(config or ReCAPConfig(window=100)).run(env, client, episode_id="e", emit=rows.append)
    return result, rows, client, env


def messages(rows: list[Any]) -> list[MessageRecord]:
    return [r for r in rows if isinstance(r, MessageRecord)]


SHORT_EPISODE = [
    plan("plan", "fix add", "run tests"),
    reply("", ("call_1", "str_replace", FIX)),
    plan("fixed"),
    reply(plan("test now", "run tests"), ("call_2", "bash", J({"command": TEST_CMD}))),
    plan("all good"),
    plan("go submit", "submit"),
    reply("", ("call_3", "submit", "{}")),
    reply("", ("call_4", "submit", "{}")),
]


def test_a_short_episode_descends_acts_returns_and_submits_twice():
    result, rows, client, env = run(SHORT_EPISODE)
    assert (result.end_reason, result.success, result.steps, result.llm_calls, result.max_depth) == ("success", True, 4, 8, 2)
    assert env.calls == [
        ("str_replace", {"path": "app.py", "old_str": "a - b", "new_str": "a + b"}),
        ("bash", {"command": TEST_CMD}),
        ("submit", {}),
        ("submit", {}),
    ]
    msgs = messages(rows)
    assert [(m.seq, m.role, m.kind, m.node_id, m.tool_call_id) for m in msgs] == [
        (0, "user", "task", None, None),
        (1, "assistant", "reply", 1, None),
        (2, "user", "descend", 2, None),
        (3, "assistant", "reply", 2, None),
        (4, "tool", "tool_result", 2, "call_1"),
        (5, "assistant", "reply", 2, None),
        (6, "user", "return", 1, None),
        (7, "assistant", "reply", 1, None),
        (8, "tool", "tool_result", 1, "call_2"),
        (9, "assistant", "reply", 1, None),
        (10, "user", "return", 0, None),
        (11, "assistant", "reply", 0, None),
        (12, "user", "descend", 3, None),
        (13, "assistant", "reply", 3, None),
        (14, "tool", "tool_result", 3, "call_3"),
        (15, "assistant", "reply", 3, None),
    ]
    assert msgs[0].content == TP.task_prompt(
        rules=env.rules(),
        observation="add(1, 2) returns -1 instead of 3.",
        goal="Fix the issue in the repository.",
        with_think=True,
    )
    assert msgs[0].pinned
    assert msgs[2].content == f"OK.\n\nYour current task: fix add\n\n{DOWN_CHOICES}"
    assert msgs[3].tool_calls == J([{"id": "call_1", "name": "str_replace", "arguments": FIX}]) and msgs[3].content == ""
    # the action-taken prompt is the tool message of the call (the release's layout)
    assert msgs[4].content == (
        "Latest observation:\nThe file app.py has been edited.\n\nYour current task: fix add\n\n"
        f"The subtasks you proposed before:\n(none)\n\n{CHOICES}"
    )
    # up to the root: the finished task, the root's task, its latest think and what remains of its list
    assert msgs[6].content == (
        "You judged the task 'fix add' to be complete.\n\n"
        "You are back at the task above it.\nYour current task: Fix the issue in the repository.\n\n"
        "Your latest reasoning for it: plan\n\nIts remaining subtasks:\n1. run tests\n\n" + CHOICES
    )
    # text and a call in one reply: the text is the node's new version, the list shown after the call
    assert msgs[8].content == (
        "Latest observation:\n1 passed\n\nYour current task: Fix the issue in the repository.\n\n"
        f"The subtasks you proposed before:\n1. run tests\n\n{CHOICES}"
    )
    # up past the root to the pre-root "review and submit": its think and its one subtask
    assert msgs[10].content == (
        "You judged the task 'Fix the issue in the repository.' to be complete.\n\n"
        "You are back at the task above it.\nYour current task: review and submit\n\n"
        f"Your latest reasoning for it: {PRE_THINK}\n\nIts remaining subtasks:\n1. submit\n\n" + CHOICES
    )
    assert msgs[14].content.startswith("Latest observation:\nReview your change, then submit again.\n<diff>\n--- a/app.py")
    # every request offers the tools with tool choice auto, never JSON mode; the purpose is the prompt's kind
    assert all(r.tools == TOOLS and r.tool_choice == "auto" and not r.json_mode for r in client.requests)
    assert [r.purpose for r in client.requests] == [
        "task",
        "descend",
        "action_taken",
        "return",
        "action_taken",
        "return",
        "descend",
        "action_taken",
    ]
    assert [(r.hints["task"], r.hints["depth"], r.hints["is_root"], r.hints["is_pre_root"]) for r in client.requests][5] == (
        "review and submit",
        0,
        False,
        True,
    )
    assert client.requests[5].hints["remaining"] == ["submit"]


def test_the_tree_has_the_pre_root_above_the_task():
    _, rows, _, _ = run(SHORT_EPISODE)
    nodes = {n.node_id: n for n in rows if isinstance(n, NodeRecord)}
    got = {i: (n.parent_id, n.depth, n.child_index, n.task, n.kind, n.status, n.step_index) for i, n in nodes.items()}
    assert got == {
        0: (None, 0, 0, "review and submit", "root", "open", None),
        1: (0, 1, 0, "Fix the issue in the repository.", "composite", "done", None),
        2: (1, 2, 0, "fix add", "primitive", "done", 0),
        3: (0, 1, 1, "submit", "primitive", "done", 2),
    }
    assert [(v.think, v.subtasks, v.call_index, v.message_seq) for v in nodes[0].versions] == [
        (PRE_THINK, ("submit",), None, None),
        ("go submit", ("submit",), 5, 11),
    ]
    assert [(v.think, v.subtasks, v.call_index) for v in nodes[1].versions] == [
        ("plan", ("fix add", "run tests"), 0),
        ("test now", ("run tests",), 3),
        ("all good", (), 4),
    ]
    assert [(v.think, v.subtasks) for v in nodes[2].versions] == [("fixed", ())]  # the tool-only reply adds none
    assert nodes[3].versions == ()
    calls = [r for r in rows if isinstance(r, ToolCallRecord)]
    assert [(c.index, c.name, c.call_id, c.message_seq, c.node_id, c.valid) for c in calls] == [
        (0, "str_replace", "call_1", 3, 2, True),
        (1, "bash", "call_2", 7, 1, True),
        (2, "submit", "call_3", 13, 3, True),
        (3, "submit", "call_4", 15, 3, True),
    ]


def test_broken_arguments_are_an_error_observation_and_the_episode_goes_on():
    replies = [
        reply(plan("edit", "fix add"), ("call_1", "str_replace", '{"path": "app.py", ')),
        reply("", ("call_2", "str_replace", FIX)),
        plan("done"),
    ]
    result, rows, _, env = run(replies + [plan("stop")])
    assert result.end_reason == "agent_done" and result.invalid_actions == 1
    msgs = messages(rows)
    assert msgs[2].role == "tool" and msgs[2].tool_call_id == "call_1"
    assert msgs[2].content.startswith("Latest observation:\nerror: arguments are not valid JSON: ")
    assert msgs[2].content.endswith(
        f"Your current task: Fix the issue in the repository.\n\nThe subtasks you proposed before:\n1. fix add\n\n{CHOICES}"
    )
    assert env.calls == [("str_replace", {"path": "app.py", "old_str": "a - b", "new_str": "a + b"})]
    # the root said it is done, then the pre-root said so too: the agent ends without submitting
    assert [m.kind for m in msgs if m.role == "user"] == ["task", "return"]


def test_prose_where_json_or_a_call_was_expected_is_repaired():
    replies = [
        "I will run the tests now.",
        reply("", ("call_1", "bash", J({"command": TEST_CMD}))),
        plan("the tests fail, but I stop here"),
        plan("stop"),
    ]
    result, rows, _, _ = run(replies)
    assert (result.end_reason, result.json_repairs) == ("agent_done", 1)
    msgs = messages(rows)
    assert [(m.role, m.kind) for m in msgs[1:4]] == [("assistant", "reply"), ("user", "repair"), ("assistant", "reply")]
    assert msgs[2].content == (
        "I could not use your last reply: no JSON object found in the reply; answer with one JSON object.\n"
        'Answer again with a single JSON object of the form {"think": "<your reasoning>", "subtasks": ["<subtask>", ...]} and nothing else.'
    )
    assert msgs[4].content.startswith("Latest observation:\n1 failed\n")


def test_several_calls_in_one_reply_each_get_their_result_the_last_the_prompt():
    replies = [
        reply("", ("call_1", "view", J({"path": "app.py"})), ("call_2", "str_replace", FIX)),
        plan("done"),
        plan("stop"),
    ]
    _, rows, _, _ = run(replies)
    tools = [(m.tool_call_id, m.content) for m in messages(rows) if m.role == "tool"]
    assert tools[0] == ("call_1", "def add(a, b):\n    return a - b\n")
    assert tools[1][0] == "call_2" and tools[1][1].startswith("Latest observation:\nThe file app.py has been edited.\n\n")


def test_a_call_that_ends_the_reply_early_answers_nothing_after_it():
    replies = [reply("", ("call_1", "submit", "{}"), ("call_2", "submit", "{}"), ("call_3", "bash", J({"command": "ls"})))]
    result, rows, _, env = run(replies)
    assert result.end_reason == "agent_done"  # the toy's final submit of an unfixed repository
    assert [c[0] for c in env.calls] == ["submit", "submit"]
    assert [m.tool_call_id for m in messages(rows) if m.role == "tool"] == ["call_1"]


def test_at_the_depth_cap_a_node_is_asked_to_act_instead_of_decomposing():
    replies = [
        plan("plan", "fix add"),  # root (level 1) -> "fix add" at depth 2 = max_level
        plan("split", "find it", "change it"),  # decomposes all the same: asked again, not descended
        reply("", ("call_1", "str_replace", FIX)),
        plan("done"),
        plan("done"),
        plan("stop"),
    ]
    result, rows, client, _ = run(replies, ReCAPConfig(window=100, max_level=2))
    assert result.end_reason == "agent_done" and result.max_depth == 2
    msgs = messages(rows)
    cap = (
        "OK.\n\nYour current task: fix add\n\nThis task may not be broken down any further. Call tools to "
        "carry it out, or reply with an empty list if it is already complete."
    )
    assert [(m.kind, m.content) for m in msgs if m.kind == "depth_cap"] == [("depth_cap", cap), ("depth_cap", cap)]
    assert [r.purpose for r in client.requests] == ["task", "depth_cap", "depth_cap", "action_taken", "return", "return"]
    nodes = [n for n in rows if isinstance(n, NodeRecord)]
    assert [n.task for n in nodes] == ["review and submit", "Fix the issue in the repository.", "fix add"]


def test_a_repaired_tool_reply_has_its_calls_answered_as_not_run():
    replies = [reply("not json", ("call_1", "bash", J({"command": "ls"}))), plan("stop"), plan("stop")]
    result, rows, _, env = run(replies)
    assert result.end_reason == "agent_done" and env.calls == []
    assert [(m.role, m.tool_call_id, m.content) for m in messages(rows) if m.role == "tool"] == [("tool", "call_1", NOT_RUN)]


def test_the_window_never_sends_a_tool_result_without_its_call():
    result, _, client, _ = run(SHORT_EPISODE, ReCAPConfig(window=4))
    assert result.end_reason == "success"
    assert [[m.role for m in r.messages] for r in client.requests] == [
        ["user"],
        ["user", "assistant", "user"],
        ["user", "assistant", "user", "assistant", "tool"],
        ["user", "assistant", "tool", "assistant", "user"],
        ["user", "assistant", "user", "assistant", "tool"],
        ["user", "assistant", "tool", "assistant", "user"],
        ["user", "assistant", "user", "assistant", "user"],
        ["user", "assistant", "user", "assistant", "tool"],
    ]
    for r in client.requests:
        for i, m in enumerate(r.messages):
            if m.role == "tool":
                assert m.tool_call_id in [c.id for c in r.messages[i - 1].tool_calls]


def test_one_call_per_reply_re_asks_a_reply_with_several_and_runs_none_of_them():
    replies = [
        reply(plan("two at once", "fix"), ("call_1", "view", J({"path": "app.py"})), ("call_2", "str_replace", FIX)),
        reply(plan("one now", "fix"), ("call_3", "str_replace", FIX)),
        plan("done"),
        plan("stop"),
    ]
    result, rows, client, env = run(replies, ReCAPConfig(window=100, tool_calls_per_reply="one"))
    assert (result.end_reason, result.json_repairs) == ("agent_done", 1)
    assert [c[0] for c in env.calls] == ["str_replace"]  # the two calls of the first reply never ran
    msgs = messages(rows)
    assert [(m.role, m.kind, m.tool_call_id) for m in msgs[1:6]] == [
        ("assistant", "reply", None),
        ("tool", "tool_result", "call_1"),
        ("tool", "tool_result", "call_2"),
        ("user", "repair", None),
        ("assistant", "reply", None),
    ]
    assert msgs[2].content == msgs[3].content == NOT_RUN
    assert msgs[4].content == (
        "Your last reply made 2 tool calls, and none of them was run: make exactly one tool call per reply, "
        "with your JSON object as the reply's text. Reply again with your first call only."
    )
    assert [r.purpose for r in client.requests] == ["task", "repair", "action_taken", "return"]


def test_one_call_per_reply_past_the_repair_budget_ends_json_failures():
    two = reply("", ("call_1", "bash", J({"command": "ls"})), ("call_2", "bash", J({"command": "ls"})))
    result, _, client, env = run([two, two], ReCAPConfig(window=100, tool_calls_per_reply="one", max_json_repairs=1))
    assert (result.end_reason, result.error, result.json_repairs, len(client.requests)) == (
        "json_failures",
        "the reply made 2 tool calls",
        1,
        2,
    )
    assert env.calls == []


def test_reply_schema_sends_the_think_subtasks_schema_and_no_think_leaves_think_out():
    result, _, client, _ = run([plan("stop"), plan("stop")], ReCAPConfig(window=100, reply_schema=True))
    assert result.end_reason == "agent_done"
    schema = {
        "name": "ReCAP",
        "schema": {
            "type": "object",
            "properties": {
                "think": {"type": "string", "description": "Your reasoning about the current task and the latest observation."},
                "subtasks": {
                    "type": "array",
                    "items": {"type": "string"},
                    "description": "The ordered subtasks still needed for the current task; empty when it is complete.",
                },
            },
            "required": ["think", "subtasks"],
            "additionalProperties": False,
        },
    }
    assert [r.response_schema for r in client.requests] == [schema, schema]
    _, _, plain, _ = run([plan("stop"), plan("stop")])
    assert [r.response_schema for r in plain.requests] == [None, None]
    _, _, bare, _ = run([J({"subtasks": []}), J({"subtasks": []})], ReCAPConfig(window=100, reply_schema=True, think="none"))
    sent = bare.requests[0].response_schema
    assert sent is not None and list(sent["schema"]["properties"]) == ["subtasks"] and sent["schema"]["required"] == ["subtasks"]
