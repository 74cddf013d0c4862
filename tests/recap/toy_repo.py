"""A toy coding environment for the tool-mode agents' tests: a dict-backed "repository" with the
SWE environment's semantics (bash / view / str_replace / submit tools; a text action is one bash
command and ``echo COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT`` submits at once; the first ``submit``
tool call shows a review with the diff, the second ends the episode; an expert plan of JSON
tool calls from the current state)."""

from __future__ import annotations

import json
import re
import shlex
from collections.abc import Mapping
from typing import Any

from recap.env import Demonstration, Environment, Reset, Step
from recap.llm import ToolDef

SENTINEL = "COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
BUGGY = "def add(a, b):\n    return a - b\n"
FIXED = "def add(a, b):\n    return a + b\n"
TEST_CMD = "python -m pytest test_app.py"

TOOLS = (
    ToolDef(
        "bash", "run one command", {"type": "object", "properties": {"command": {"type": "string"}}, "required": ["command"]}
    ),
    ToolDef("view", "show a file", {"type": "object", "properties": {"path": {"type": "string"}}, "required": ["path"]}),
    ToolDef(
        "str_replace",
        "replace text that occurs once",
        {
            "type": "object",
            "properties": {"path": {"type": "string"}, "old_str": {"type": "string"}, "new_str": {"type": "string"}},
            "required": ["path", "old_str", "new_str"],
        },
    ),
    ToolDef("submit", "hand in the change (first: review, second: final)"),
)

_PY_EDIT = re.compile(r"^python3 - <<'EOF'\n(?P<body>.*)\nEOF$", re.S)


class ToyRepo(Environment):
    """``app.py`` holds a bug (``a - b``); the test passes once it reads ``a + b``."""

    benchmark = "toy_swe"
    instance_id = "toy_swe/add@0"
    invalid_action_mode = "step"
    max_steps = 30

    def __init__(self) -> None:
        self.files: dict[str, str] = {}
        self.submit_stage = 0
        self.viewed: set[str] = set()
        self.tested = False
        self.done = False
        self.calls: list[tuple[str, dict[str, Any]]] = []

    def reset(self) -> Reset:
        self.files = {"app.py": BUGGY, "test_app.py": "assert add(1, 2) == 3\n"}
        self.submit_stage, self.viewed, self.tested, self.done = 0, set(), False, False
        return Reset("add(1, 2) returns -1 instead of 3.", None, "Fix the issue in the repository.")

    def tool_defs(self) -> tuple[ToolDef, ...]:
        return TOOLS

    def rules(self) -> str:
        return "A Python repository with app.py and test_app.py."

    def demonstration(self) -> Demonstration | None:
        return None

    def diff(self) -> str:
        if self.files["app.py"] == BUGGY:
            return ""
        return f"--- a/app.py\n+++ b/app.py\n-{BUGGY}+{self.files['app.py']}"

    def _bash(self, command: str) -> tuple[str, int]:
        m = _PY_EDIT.match(command)
        if m:  # the offline expert's edit script: run it on the dict (it only uses pathlib)
            scope: dict[str, Any] = {}
            body = m.group("body").replace("import pathlib\n", "")
            fs = self.files

            class _Path:
                def __init__(self, p: str) -> None:
                    self.p = p

                def read_text(self) -> str:
                    return fs[self.p]

                def write_text(self, text: str) -> None:
                    fs[self.p] = text

            scope["pathlib"] = type("pathlib", (), {"Path": _Path})
            try:
                exec(body, scope)  # noqa: S102 (a test double's own script)
            except AssertionError as exc:
                return f"AssertionError: {exc}", 1
            return "", 0
        words = shlex.split(command)
        if words[:1] == ["echo"]:
            return " ".join(words[1:]), 0
        if words[:2] == ["cat", "-n"] and words[2] in self.files:
            self.viewed.add(words[2])
            return "\n".join(f"{i:6}\t{line}" for i, line in enumerate(self.files[words[2]].splitlines(), 1)), 0
        if command == TEST_CMD:
            self.tested = True
            ok = self.files["app.py"] == FIXED
            return ("1 passed" if ok else "1 failed"), (0 if ok else 1)
        return f"bash: {words[0] if words else ''}: command not found", 127

    def step(self, action: str) -> Step:
        self.calls.append(("bash", {"command": action}))
        out, code = self._bash(action)
        if out.split("\n", 1)[0].strip() == SENTINEL:
            return self._final()
        return Step(out, None, False, False, {"exit_code": code, "tool": "bash"})

    def call_tool(self, name: str, args: Mapping[str, Any]) -> Step:
        self.calls.append((name, dict(args)))
        if name == "bash":
            out, code = self._bash(str(args["command"]))
            return Step(out, None, False, False, {"exit_code": code})
        if name == "view":
            path = str(args.get("path", ""))
            if path not in self.files:
                return Step(f"Error: {path} does not exist", None, False, False, {"error": "no such file"})
            self.viewed.add(path)
            return Step(self.files[path], None, False, False, {"exit_code": 0})
        if name == "str_replace":
            path, old = str(args.get("path", "")), str(args.get("old_str", ""))
            text = self.files.get(path, "")
            if text.count(old) != 1:
                return Step("Error: old_str does not occur exactly once", None, False, False, {"error": "no unique match"})
            self.files[path] = text.replace(old, str(args.get("new_str", "")), 1)
            return Step(f"The file {path} has been edited.", None, False, False, {"exit_code": 0})
        if self.submit_stage == 0:
            self.submit_stage = 1
            return Step(f"Review your change, then submit again.\n<diff>\n{self.diff()}</diff>", None, False, False, {})
        return self._final()

    def _final(self) -> Step:
        self.done = True
        ok = self.files["app.py"] == FIXED
        return Step("submitted", None, True, ok, {} if ok else {"end_reason": "agent_done"})

    def expert_plan(self) -> list[str] | None:
        if self.done:
            return None
        calls: list[dict[str, Any]] = []
        if self.files["app.py"] != FIXED:
            if "app.py" not in self.viewed:
                calls.append({"name": "view", "arguments": {"path": "app.py"}})
            calls.append({"name": "str_replace", "arguments": {"path": "app.py", "old_str": "a - b", "new_str": "a + b"}})
        if self.submit_stage == 0 and not self.tested:
            calls.append({"name": "bash", "arguments": {"command": TEST_CMD}})
        calls += [{"name": "submit", "arguments": {}}] * (2 - self.submit_stage)
        return [json.dumps(c) for c in calls]


def tool_plan(env: ToyRepo) -> list[dict[str, Any]]:
    """The expert plan as objects (for assertions)."""
    return [json.loads(c) for c in env.expert_plan() or []]
