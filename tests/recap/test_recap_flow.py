"""ReCAP's exact message sequence on scripted episodes: descent with plan-ahead, the shortcut,
leaf success with and without remaining subtasks, non-leaf return, judge-done, leaf failure,
root completion and the tree records."""

from __future__ import annotations

import json

from recap.blocksworld import DEMONSTRATION, RULES
from tests.recap.recap_harness import demo_env, run_recap

SCRIPT = DEMONSTRATION.replies["recap"]

OBS0 = (
    "Tower on the table: A, C (top: C)\n"
    "Tower on the table: B (top: B)\n"
    "The gripper is empty.\n"
    "Valid Actions:\n"
    "pick up B\n"
    "unstack C from A"
)
OBS1 = (
    "Tower on the table: A (top: A)\n"
    "Tower on the table: B (top: B)\n"
    "The gripper holds C.\n"
    "Valid Actions:\n"
    "put down C\n"
    "stack C on A\n"
    "stack C on B"
)
OBS2 = (
    "Tower on the table: A (top: A)\n"
    "Tower on the table: B (top: B)\n"
    "Tower on the table: C (top: C)\n"
    "The gripper is empty.\n"
    "Valid Actions:\n"
    "pick up A\n"
    "pick up B\n"
    "pick up C"
)
GOAL = "Build one tower with A on the table, then B on A, then C on B."


def test_full_episode_message_sequence():
    run = run_recap(list(SCRIPT))
    assert run.result.end_reason == "success"
    assert run.result.success and run.result.steps == 6 and run.result.llm_calls == 9
    assert [(m.seq, m.role, m.kind) for m in run.messages] == [
        (0, "user", "task"),
        (1, "assistant", "reply"),
        (2, "user", "descend"),
        (3, "assistant", "reply"),
        (4, "user", "leaf_done"),
        (5, "assistant", "reply"),
        (6, "user", "leaf_judge"),
        (7, "assistant", "reply"),
        (8, "user", "nonleaf_done"),
        (9, "assistant", "reply"),
        (10, "user", "descend"),
        (11, "assistant", "reply"),
        (12, "user", "leaf_done"),
        (13, "assistant", "reply"),
        (14, "user", "leaf_done"),
        (15, "assistant", "reply"),
        (16, "user", "leaf_done"),
        (17, "assistant", "reply"),
    ]
    assert [m.pinned for m in run.messages].count(True) == 1 and run.messages[0].pinned
    # the pinned task prompt: system text, rules, first observation, goal, plan-ahead request
    task = run.messages[0].content
    assert task.startswith("You are an agent that reaches a goal in an environment by planning recursively.")
    assert f"Rules of the environment:\n{RULES}" in task
    assert task.endswith(
        f"Initial observation:\n{OBS0}\n\nYour goal:\n{GOAL}\n\n"
        "Begin the task: first write a list of high-level subtasks that together reach the goal."
    )
    # descent into a composite subtask
    assert run.messages[2].content == "OK.\n\nYour current task: clear block A\n\nWrite the list of subtasks for this task."
    # shortcut: "unstack C from A" is a valid action -> executed without a call; leaf return with remaining
    assert run.messages[4].content == (
        "You have completed the task: unstack C from A\n\n"
        f"Result:\n{OBS1}\n\n"
        "You are back at the task above it.\nYour current task: clear block A\n\n"
        "Your reasoning so far: Only C is on A, so moving C to the table clears it.\n\n"
        "Your remaining subtasks:\n1. put down C\n\n"
        "Revise the remaining subtasks in light of the latest observation so that the goal is reached. "
        "If none are needed any more, check whether the current task is complete and reply with an empty "
        "list if it is. Do not add subtasks outside the current task."
    )
    # leaf success with nothing remaining -> judge-done
    assert run.messages[6].content == (
        "You have completed the task: put down C\n\n"
        f"Result:\n{OBS2}\n\n"
        "You are back at the task above it.\nYour current task: clear block A\n\n"
        "Your reasoning so far: I hold C; putting it down leaves A clear.\n\n"
        "No subtasks are left. Decide whether the current task is complete: if it is, reply with an "
        "empty list; if not, list the subtasks still needed."
    )
    # non-leaf return to the root re-injects the root's think and remaining subtasks
    assert run.messages[8].content == (
        "You have completed the task: clear block A\n\n"
        "Its results are in the conversation above.\n\n"
        f"You are back at the task above it.\nYour current task: {GOAL}\n\n"
        "Your reasoning so far: A must be the base, but C is sitting on it. First clear A, then build B and C on top.\n\n"
        "Your remaining subtasks:\n1. build B on A and C on B\n\n"
        "Revise the remaining subtasks in light of the latest observation so that the goal is reached. "
        "If none are needed any more, check whether the current task is complete and reply with an empty "
        "list if it is. Do not add subtasks outside the current task."
    )
    # assistant messages are the model's replies verbatim
    assert json.loads(run.messages[1].content) == dict(SCRIPT[0])
    assert [s.action for s in run.steps] == [
        "unstack C from A",
        "put down C",
        "pick up B",
        "stack B on A",
        "pick up C",
        "stack C on B",
    ]
    assert all(s.valid for s in run.steps) and run.steps[-1].success and run.steps[-1].done


def test_calls_reference_their_window_and_reply():
    run = run_recap(list(SCRIPT))
    assert [c.call_index for c in run.calls] == list(range(9))
    assert [c.purpose for c in run.calls] == [
        "task",
        "descend",
        "leaf_done",
        "leaf_judge",
        "nonleaf_done",
        "descend",
        "leaf_done",
        "leaf_done",
        "leaf_done",
    ]
    assert run.calls[0].window_seqs == (0,)
    assert run.calls[3].window_seqs == (0, 1, 2, 3, 4, 5, 6)
    assert [c.response_seq for c in run.calls] == [1, 3, 5, 7, 9, 11, 13, 15, 17]
    assert all(c.status == "ok" and c.test_double for c in run.calls)
    # the requests the model saw are exactly the window
    req = run.client.requests[3]
    assert [m.content for m in req.messages] == [m.content for m in run.messages[:7]]
    assert req.hints["task"] == "clear block A" and req.hints["remaining"] == []
    assert req.hints["depth"] == 1 and req.hints["style"] == "recap"


def test_tree_records():
    run = run_recap(list(SCRIPT))
    nodes = {n.node_id: n for n in run.nodes}
    assert [(n.node_id, n.parent_id, n.depth, n.child_index, n.task, n.kind, n.status) for n in run.nodes] == [
        (0, None, 0, 0, GOAL, "root", "open"),
        (1, 0, 1, 0, "clear block A", "composite", "done"),
        (2, 1, 2, 0, "unstack C from A", "primitive", "done"),
        (3, 1, 2, 1, "put down C", "primitive", "done"),
        (4, 0, 1, 1, "build B on A and C on B", "composite", "open"),
        (5, 4, 2, 0, "pick up B", "primitive", "done"),
        (6, 4, 2, 1, "stack B on A", "primitive", "done"),
        (7, 4, 2, 2, "pick up C", "primitive", "done"),
        (8, 4, 2, 3, "stack C on B", "primitive", "done"),
    ]
    # versions: every (think, subtasks) the node had, with the call and message that produced it
    assert [(v.version, v.subtasks, v.call_index, v.message_seq) for v in nodes[1].versions] == [
        (0, ("unstack C from A", "put down C"), 1, 3),
        (1, ("put down C",), 2, 5),
        (2, (), 3, 7),
    ]
    # a shortcut leaf has one synthetic version and no call
    assert [(v.think, v.subtasks, v.call_index) for v in nodes[2].versions] == [(None, ("unstack C from A",), None)]
    assert nodes[2].step_index == 0 and nodes[8].step_index == 5
    assert len(nodes[0].versions) == 2 and nodes[0].versions[1].subtasks == ("build B on A and C on B",)


def test_tree_is_reconstructed_from_node_and_message_records():
    run = run_recap(list(SCRIPT))
    by_seq = {m.seq: m for m in run.messages}
    children: dict[int | None, list[int]] = {}
    for n in sorted(run.nodes, key=lambda n: (n.parent_id if n.parent_id is not None else -1, n.child_index)):
        children.setdefault(n.parent_id, []).append(n.node_id)
    assert children == {None: [0], 0: [1, 4], 1: [2, 3], 4: [5, 6, 7, 8]}
    for n in run.nodes:
        for v in n.versions:
            if v.message_seq is None:
                continue
            reply = json.loads(by_seq[v.message_seq].content)
            assert (reply["think"], tuple(reply["subtasks"])) == (v.think, v.subtasks)
            assert by_seq[v.message_seq].node_id == n.node_id
        # each child's task is the head of its parent's list at the time it was created
        if n.parent_id is not None:
            parent = next(p for p in run.nodes if p.node_id == n.parent_id)
            assert any(v.subtasks and v.subtasks[0] == n.task for v in parent.versions)


def test_leaf_failure_takes_no_step_and_reinjects_full_list():
    replies = [
        {"think": "Grab C first.", "subtasks": ["grab C", "put down C"]},
        {"think": "Grabbing is one action.", "subtasks": ["grab C"]},  # one item, not valid -> leaf failure
        {"think": "The verb is unstack.", "subtasks": []},  # root gives up
    ]
    run = run_recap(replies)
    assert run.result.end_reason == "agent_done" and not run.result.success
    assert run.result.steps == 0 and run.result.invalid_actions == 1
    assert [(s.action, s.valid, s.env_step, s.observation) for s in run.steps] == [("grab C", False, 0, OBS0)]
    assert run.kinds() == ["task", "reply", "descend", "reply", "leaf_fail", "reply"]
    from recap.blocksworld import HINTS

    assert run.messages[4].content == (
        "You could not complete the task: grab C\n\n"
        "The action is not one of the valid actions, so nothing was done.\n\n"
        f"Current observation:\n{OBS0}\n\n"
        f"Common causes:\n{HINTS}\n\n"
        f"You are back at the task above it.\nYour current task: {GOAL}\n\n"
        "Your reasoning so far: Grab C first.\n\n"
        "Your remaining subtasks:\n1. grab C\n2. put down C\n\n"
        "Change your list of subtasks so that the error is fixed."
    )
    failed = [n for n in run.nodes if n.status == "failed"]
    assert [(n.task, n.kind, n.step_index) for n in failed] == [("grab C", "primitive", 0)]


def test_leaf_failure_names_the_proposed_action_when_it_differs():
    replies = [
        {"think": "t", "subtasks": ["move C away", "x"]},
        {"think": "u", "subtasks": ["lift C"]},
        {"think": "v", "subtasks": []},
    ]
    run = run_recap(replies)
    assert run.user("leaf_fail")[0].startswith(
        "You could not complete the task: move C away\n\nThe action ('lift C') is not one of the valid actions, so nothing was done."
    )


def test_root_empty_list_ends_the_episode():
    run = run_recap([{"think": "Nothing to do.", "subtasks": []}])
    assert run.result.end_reason == "agent_done" and run.result.llm_calls == 1 and run.result.steps == 0
    assert [(n.node_id, n.status) for n in run.nodes] == [(0, "done")]


def test_empty_descend_reply_returns_as_nonleaf():
    replies = [
        {"think": "a", "subtasks": ["check the table", "unstack C from A"]},
        {"think": "b", "subtasks": []},  # child says it has nothing to do
        {"think": "c", "subtasks": []},
    ]
    run = run_recap(replies)
    assert run.kinds() == ["task", "reply", "descend", "reply", "nonleaf_done", "reply"]
    assert "Your remaining subtasks:\n1. unstack C from A" in run.messages[4].content


def test_one_valid_action_reply_executes_as_leaf():
    replies = [
        {"think": "a", "subtasks": ["free A", "pick up B"]},
        {"think": "b", "subtasks": ["unstack C from A"]},
        {"think": "c", "subtasks": []},
    ]
    run = run_recap(replies)
    assert [s.action for s in run.steps] == ["unstack C from A"]
    assert run.kinds()[4] == "leaf_done"
    assert run.messages[4].content.startswith(f"You have completed the task: free A\n\nResult:\n{OBS1}")
    node = next(n for n in run.nodes if n.task == "free A")
    assert node.kind == "primitive" and node.status == "done" and node.versions[0].call_index == 1


def test_env_is_unchanged_after_leaf_failure():
    env = demo_env()
    run = run_recap(
        [{"think": "a", "subtasks": ["fly"]}, {"think": "b", "subtasks": ["fly"]}, {"think": "c", "subtasks": []}], env=env
    )
    assert run.result.steps == 0
    assert env.expert_plan() == ["unstack C from A", "put down C", "pick up B", "stack B on A", "pick up C", "stack C on B"]
