"""The authors' printed GPT-4o FEVER runs, read at test time from the ReAct/Act notebooks' saved output.

``fever-recap/React.ipynb`` and ``baseline_act.ipynb`` (cell 4) print, per claim: ``<idx> Claim: ...``
(``print(idx, question)``), for each step the ``step_str`` the loop built (``Thought i: <thought>\\nAction
i: <action>\\nObservation i: <obs>\\n``, ReAct; Act without the thought) after a line ``ohh... <reply>``
when ReAct's reply did not split, the ``info`` dict, then the running ``sum(rs) len(rs) ...`` line.
This module parses that text back into episodes: what the model answered to each call (the reply as
``llm`` returned it, stripped), the action stepped and the observation returned, and the printed
``em``. Nothing of the notebooks is stored in the repository; they are read from
``../shared/data/recap-release``.
"""

from __future__ import annotations

import ast
import json
import re
from dataclasses import dataclass, field

from tests.conftest import SHARED_DATA

RELEASE = SHARED_DATA / "recap-release"
FEVER = RELEASE / "fever-recap"
NOTEBOOKS = {"react": "React.ipynb", "act": "baseline_act.ipynb"}
#: the loop cell (React.ipynb / baseline_act.ipynb cell 4)
LOOP_CELL = 4
_EPISODE = re.compile(r"(?m)^(\d+) Claim: (.*)$")
_RUNNING = re.compile(r"(?m)^(\d+) (\d+) [0-9.e-]+ [0-9.e-]+\n-----------\n")


@dataclass
class Call:
    """One model call: the reply the notebook's ``llm`` returned and the stop list it was called with."""

    reply: str
    stop: tuple[str, ...]


@dataclass
class Step:
    """One printed step: the thought (ReAct; None for Act), the action as printed, the observation,
    and the calls the step made (one; two where ReAct re-asked)."""

    thought: str | None
    action: str
    observation: str
    calls: list[Call] = field(default_factory=list)
    bad: bool = False


@dataclass
class Episode:
    """One claim's printed run."""

    index: int
    claim: str
    steps: list[Step]
    info: dict
    running_sum: int


def output_text(method: str) -> str:
    """The loop cell's printed output."""
    cells = json.loads((FEVER / NOTEBOOKS[method]).read_text(encoding="utf-8-sig"))["cells"]
    return "".join("".join(o.get("text", "")) for o in cells[LOOP_CELL].get("outputs", []))


def _blocks(text: str) -> list[tuple[int, str, str]]:
    starts = list(_EPISODE.finditer(text))
    out = []
    for n, m in enumerate(starts):
        end = starts[n + 1].start() if n + 1 < len(starts) else len(text)
        out.append((int(m.group(1)), m.group(2), text[m.end() + 1 : end]))
    return out


def _split_info(body: str) -> tuple[str, dict, int]:
    """The steps' text, the printed info dict, the running sum after the episode."""
    info_at = body.rfind("\n{'steps'")
    if body.startswith("{'steps'"):
        info_at = -1
    info_line_end = body.index("\n", info_at + 1)
    info = ast.literal_eval(body[info_at + 1 : info_line_end].strip())
    running = _RUNNING.search(body, info_line_end)
    assert running is not None, body[-300:]
    return body[: max(info_at, 0)], info, int(running.group(1))


def _parse_react_steps(text: str) -> list[Step]:
    steps: list[Step] = []
    pos = 0
    i = 1
    while pos < len(text):
        bad = text.startswith("ohh... ", pos)
        head = f"Thought {i}: "
        if bad:
            first_line = text[pos + len("ohh... ") :].split("\n", 1)[0]
            marker = f"\n{head}{first_line}\nAction {i}: "
            at = text.index(marker, pos)
            reply = text[pos + len("ohh... ") : at]
            pos = at + 1
        assert text.startswith(head, pos), (i, text[pos : pos + 200])
        obs_marker = f"\nObservation {i}: "
        act_marker = f"\nAction {i}: "
        obs_at = text.index(obs_marker, pos)
        act_at = text.rindex(act_marker, pos, obs_at)
        thought = text[pos + len(head) : act_at]
        action = text[act_at + len(act_marker) : obs_at]
        obs_start = obs_at + len(obs_marker)
        nxt = _next_step(text, obs_start + _echo_length(text, obs_start, action), i + 1, "Thought")
        obs = text[obs_start : nxt - 2]  # step_str ends "\n", print adds one
        calls = [Call(f"{thought}\nAction {i}: {action}", (f"\nObservation {i}:",))]
        if bad:
            calls = [Call(reply, (f"\nObservation {i}:",)), Call(action, ("\n",))]
        steps.append(Step(thought, action, obs, calls, bad))
        pos = nxt
        i += 1
    return steps


def _parse_act_steps(text: str) -> list[Step]:
    steps: list[Step] = []
    pos = 0
    i = 1
    while pos < len(text):
        head = f"Action {i}: "
        assert text.startswith(head, pos), (i, text[pos : pos + 200])
        obs_marker = f"\nObservation {i}: "
        obs_at = text.index(obs_marker, pos)
        action = text[pos + len(head) : obs_at]
        obs_start = obs_at + len(obs_marker)
        nxt = _next_step(text, obs_start + _echo_length(text, obs_start, action), i + 1, "Action")
        obs = text[obs_start : nxt - 2]
        # the notebook keeps split("Action i:")[-1].strip() of the reply: the printed action is a
        # reply that yields it (the model's own text before it is not printed)
        steps.append(Step(None, action, obs, [Call(action, (f"\nObservation {i}:",))]))
        pos = nxt
        i += 1
    return steps


def _echo_length(text: str, start: int, action: str) -> int:
    """How long the observation at ``start`` is at least: an invalid action is echoed whole
    (``Invalid action: <action>``, wikienv.py:156), and an echo may itself hold a later round's label."""
    return len("Invalid action: ") + len(action.strip()) if text.startswith("Invalid action: ", start) else 0


def _next_step(text: str, start: int, i: int, label: str) -> int:
    """Where the next printed step starts after an observation beginning at ``start``."""
    candidates = [text.find(f"\n\n{label} {i}: ", start), text.find("\n\nohh... ", start)]
    found = [c for c in candidates if c >= 0]
    return min(found) + 2 if found else len(text) + 1  # the last: obs, then step_str's own newline


def episodes(method: str) -> list[Episode]:
    """The 200 printed episodes of ``method`` (``react`` or ``act``) in the notebook's order."""
    out = []
    for index, claim, body in _blocks(output_text(method)):
        steps_text, info, running = _split_info(body)
        steps = _parse_react_steps(steps_text) if method == "react" else _parse_act_steps(steps_text)
        out.append(Episode(index, claim, steps, info, running))
    return out


def available() -> bool:
    """Whether the release copy with the notebooks is beside the checkout."""
    return all((FEVER / name).is_file() for name in NOTEBOOKS.values()) and (FEVER / "prompts" / "fever.json").is_file()
