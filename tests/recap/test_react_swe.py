"""ReAct as mini-SWE-agent runs it (recap/baselines/react_swe.py) on a toy coding environment: the
exact prompts, the format-error path and its bound, the submit sentinel."""

from __future__ import annotations

import json
from typing import Any

from recap.baselines import react_swe_prompts as S
from recap.baselines.react import ReActAgent, ReActConfig
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord, ToolCallRecord
from tests.recap.toy_repo import TEST_CMD, ToyRepo

EDIT = (
    'python3 - <<\'EOF\'\nimport pathlib\np = pathlib.Path("app.py")\np.write_text(p.read_text().replace("a - b", "a + b"))\nEOF'
)


def turn(thought: str, *commands: str) -> str:
    return f"THOUGHT: {thought}\n\n" + "\n\n".join(f"```bash\n{c}\n```" for c in commands)


def run(replies: list[Any], **settings: Any) -> tuple[Any, list[Any], ScriptedClient, ToyRepo]:
    rows: list[Any] = []
    env = ToyRepo()
    client = ScriptedClient(replies)
    result = ReActAgent(ReActConfig(window=100, **settings)).run(env, client, episode_id="e", emit=rows.append)
    return result, rows, client, env


def test_one_command_per_reply_and_the_sentinel_submits():
    replies = [
        turn("look at the code", "cat -n app.py"),
        turn("fix it", EDIT),
        turn("check", TEST_CMD),
        turn("done", S.SUBMIT_COMMAND),
    ]
    result, rows, client, env = run(replies)
    assert (result.end_reason, result.success, result.steps, result.llm_calls) == ("success", True, 4, 4)
    assert [c for c in env.calls] == [("bash", {"command": c}) for c in ("cat -n app.py", EDIT, TEST_CMD, S.SUBMIT_COMMAND)]
    msgs = [r for r in rows if isinstance(r, MessageRecord)]
    assert [(m.role, m.kind) for m in msgs] == [("user", "task")] + [("assistant", "reply"), ("user", "observation")] * 3 + [
        ("assistant", "reply")
    ]
    assert msgs[0].content == S.task_prompt(
        rules=env.rules(), issue="add(1, 2) returns -1 instead of 3.", goal="Fix the issue in the repository."
    )
    assert msgs[0].content.startswith(
        "You are an assistant that solves programming tasks by working in a computer shell over several turns."
    )
    assert msgs[0].content.endswith(
        "submit it by running exactly this command on its own:\n```bash\necho COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT\n```\n"
        "After that you cannot continue."
    )
    assert msgs[2].content == "<returncode>0</returncode>\n<output>\n     1\tdef add(a, b):\n     2\t    return a - b\n</output>"
    assert msgs[6].content == "<returncode>0</returncode>\n<output>\n1 passed\n</output>"
    # text only: no tools offered, no JSON mode (whatever the config says), the layout hint for test doubles
    assert all(not r.tools and r.tool_choice is None and not r.json_mode for r in client.requests)
    assert client.requests[0].hints["text_layout"] == "bash_block"
    # each command the environment reports as a bash run is a tool_calls row (the toy's submit reports none)
    assert [(r.name, r.arguments, r.call_id) for r in rows if isinstance(r, ToolCallRecord)] == [
        ("bash", json.dumps({"command": c}), None) for c in ("cat -n app.py", EDIT, TEST_CMD)
    ]


def test_no_block_or_two_blocks_get_a_format_error_and_are_asked_again():
    replies = ["I think the bug is in app.py.", turn("two", "ls", "pwd"), turn("done", S.SUBMIT_COMMAND)]
    result, rows, client, _ = run(replies)
    assert (result.end_reason, result.json_repairs, result.steps) == ("agent_done", 2, 1)
    msgs = [r for r in rows if isinstance(r, MessageRecord)]
    assert [(m.role, m.kind) for m in msgs[1:6]] == [
        ("assistant", "reply"),
        ("user", "format_error"),
        ("assistant", "reply"),
        ("user", "format_error"),
        ("assistant", "reply"),
    ]
    assert msgs[2].content == (
        "Your reply had 0 bash code blocks; it must have exactly one. Write a THOUGHT section, then exactly one "
        "bash block with one command:\nTHOUGHT: <your reasoning>\n\n```bash\n<exactly one command>\n```\n"
        "To submit when you are done, the command is `echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT` on its own."
    )
    assert msgs[4].content.startswith("Your reply had 2 bash code blocks; it must have exactly one.")
    assert [r.purpose for r in client.requests] == ["task", "format_error", "format_error"]


def test_format_errors_in_a_row_are_bounded():
    result, _, client, env = run(["no block"] * 3, max_json_repairs=2)
    assert (result.end_reason, result.json_repairs, result.steps) == ("json_failures", 2, 0)
    assert result.error == "3 replies in a row without exactly one bash block"
    assert len(client.requests) == 3 and env.calls == []


def test_a_long_output_shows_its_head_and_tail():
    out = "x" * 6000 + "y" * 6000
    text = S.observation_prompt(out, 1)
    assert text == (
        "<returncode>1</returncode>\n<warning>The output was too long: its first and last 5000 characters are shown "
        "and 2000 in between are left out. Use a command that prints less (grep, head, tail, sed -n).</warning>\n"
        f"<output_head>\n{'x' * 5000}\n</output_head>\n<elided_chars>2000</elided_chars>\n<output_tail>\n{'y' * 5000}\n</output_tail>"
    )
    assert S.observation_prompt("ok", None) == "<output>\nok\n</output>"
