"""``prompts: release`` for ReCAP on FEVER: a unit planned through the spec plays an episode whose
every request equals what the authors' own loop sends.

The released loop (``fever-recap/MATRIX/MATRIX/chatbot.py``: ``chatbot()``, ``ChatGPTWithMemory``,
``call_llm``) is loaded from ``../shared/data/recap-release`` in this test and driven with the
same scripted replies and the observations our environment gave (after hotpotqa_simulator.py:42's
replace), its OpenAI client replaced by a recorder; the demonstration it frames is read from
fever_matrix.json as prompts.py:2-5 reads it. Nothing of the release is stored here.
"""

from __future__ import annotations

import json
import sys
import tomllib
import types
from pathlib import Path
from typing import Any

import pytest

from pipeline.spec import parse_spec
from pipeline.units import expand
from recap.scripted import ScriptedClient
from workers.episode_worker import EpisodeRunner
from workers.release import fever_matrix

ROOT = Path(__file__).resolve().parents[4]
RELEASE = ROOT.parent / "shared" / "data" / "recap-release"
FEVER = RELEASE / "fever-recap"
pytestmark = pytest.mark.skipif(
    not (FEVER / "MATRIX" / "MATRIX" / "chatbot.py").is_file(), reason=f"no release copy at {RELEASE}"
)

ENTITY = "Nikolaj Coster-Waldau"


def reply(think: str, *subtasks: str) -> str:
    """A reply in a JSON code fence, which the released loop removes (chatbot.py:9, 12-18)."""
    return "```json\n" + json.dumps({"think": think, "subtasks": list(subtasks)}) + "\n```"


#: 31 calls reaching every prompt of the released loop: a failed action (no step), a search, a
#: lookup, two replies it cannot use (each answered, the prompt sent again, the 10th call's with
#: the reminder), failing rounds past 32 messages (the cut), two
#: composite subtasks (the non-leaf returns, with and without subtasks left, and a leaf return
#: with none left), the root's list emptied and the final answer
SCRIPT = [
    reply("plan", "find the actor", "check Fox", "decide"),  # the root
    reply("a1", "search the actor"),  # not an action: the fail prompt
    reply("plan2", f"Search[{ENTITY}]", "check Fox", "decide"),
    reply("s", f"Search[{ENTITY}]"),
    reply("plan3", "check Fox", "decide"),
    reply("c", "Lookup[Fox]"),
    reply("plan4", "check Fox", "decide"),
    "Let me look again.",  # not JSON: the error message, the same prompt again (chatbot.py:461-464)
    json.dumps({"think": "no list"}),  # no subtasks: the other error message (:465-466), again
]
for i in range(5):
    SCRIPT += [reply(f"x{i}", "look again"), reply(f"plan{5 + i}", "check Fox", "decide")]
    if i == 2:  # a third unusable reply: an odd message, so a call sees 33 messages (chatbot.py:42-45)
        SCRIPT.append("{not json")
SCRIPT += [
    reply("comp", "Lookup[Fox]", "judge it"),  # 'check Fox' is composite
    reply("y", "Lookup[Fox]"),
    reply("comp2"),  # back in 'check Fox' (a leaf return, a subtask left): done, so back to the root
    reply("plan10", "decide"),  # the root after a non-leaf return with a subtask left
    reply("d", "Lookup[Fox]", "conclude"),  # 'decide' is composite
    reply("g", "Lookup[Fox]"),
    reply("d2", "Lookup[Sun]"),
    reply("g2", "Lookup[Sun]"),
    reply("d3"),  # a leaf return with nothing left, then done
    reply("end"),  # the root after a non-leaf return with nothing left: the list empties
    reply("final", "Finish[SUPPORTS]"),
]


def _load_release_chatbot(monkeypatch: pytest.MonkeyPatch, sent: list[list[tuple[str, str]]]) -> types.ModuleType:
    """chatbot.py as a module, its imports stubbed: ``openai`` (a recording client answering from
    SCRIPT) and ``.prompt_llm`` (used for ``time`` only)."""
    replies = iter(SCRIPT)

    class Completions:
        def create(self, model: str, messages: list[dict[str, str]], **_kw: Any) -> Any:
            sent.append([(m["role"], m["content"]) for m in messages])
            message = types.SimpleNamespace(content=next(replies))
            return types.SimpleNamespace(choices=[types.SimpleNamespace(message=message)])

    openai = types.ModuleType("openai")
    openai.OpenAI = lambda api_key=None: types.SimpleNamespace(chat=types.SimpleNamespace(completions=Completions()))  # type: ignore[attr-defined]
    openai.BadRequestError = type("BadRequestError", (Exception,), {})  # type: ignore[attr-defined]
    package = types.ModuleType("released_matrix")
    package.__path__ = []
    prompt_llm = types.ModuleType("released_matrix.prompt_llm")
    prompt_llm.time = __import__("time")  # type: ignore[attr-defined]
    for name, module in {"openai": openai, "released_matrix": package, "released_matrix.prompt_llm": prompt_llm}.items():
        monkeypatch.setitem(sys.modules, name, module)
    module = types.ModuleType("released_matrix.chatbot")
    module.__package__ = "released_matrix"
    path = FEVER / "MATRIX" / "MATRIX" / "chatbot.py"
    exec(compile(path.read_text(encoding="utf-8"), str(path), "exec"), module.__dict__)
    return module


def _released_requests(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, task: str, observations: list[str]
) -> tuple[list[list[tuple[str, str]]], list[str]]:
    """Every request the released loop sends, and the actions it yields, fed ``observations``
    (one per action, as hotpotqa_simulator.py:34-42 hands them back)."""
    sent: list[list[tuple[str, str]]] = []
    chatbot = _load_release_chatbot(monkeypatch, sent)
    (tmp_path / "logs").mkdir()
    monkeypatch.chdir(tmp_path)  # chatbot.py:319-320 writes its logs under ./logs
    config = tomllib.loads((FEVER / "conf" / "config.toml").read_text(encoding="utf-8-sig"))
    few_shot = json.loads((FEVER / "prompts" / "fever_matrix.json").read_text(encoding="utf-8"))  # prompts.py:3
    first_obs = fever_matrix.first_observation((FEVER / "hotpotqa" / "hotpotqa_simulator.py").read_text(encoding="utf-8-sig"))
    gen = chatbot.chatbot(
        system_prompt=config["system_description"],
        few_shot_list=few_shot,
        task_name=task,
        init_obs=first_obs,
        rule=config["rule_description"],
        valid_actions=["Search", "Lookup", "Finish"],
    )
    actions = [next(gen)]
    for obs in observations[:-1]:
        actions.append(gen.send((obs.replace("\\n", ""), ["Search", "Lookup", "Finish"])))
    return sent, actions


class _Factory:
    writes_llm_calls = False

    def __init__(self) -> None:
        self.clients: list[ScriptedClient] = []

    def client(self, model: str) -> ScriptedClient:
        self.clients.append(ScriptedClient(SCRIPT))
        return self.clients[-1]


def test_a_release_prompts_recap_unit_sends_what_the_released_loop_sends(claims_dir, standin, tmp_path, monkeypatch):
    monkeypatch.setenv("RECAP_RELEASE_DATA", str(RELEASE))
    spec = f"""run: fever-release
output: {tmp_path / "run"}
models:
  - model: offline/expert
methods:
  - method: recap
    profile: released
    prompts: release
environments:
  - benchmark: fever
    instances: ["fever/1001"]
    options: {{data_dir: "{claims_dir}", wikipedia_url: "{standin.base_url}"}}
seeds: [0]
"""
    unit = expand(parse_spec(spec, "sweep.yaml")).units[0]  # accepted: planned with the release's digest
    assert json.loads(unit.method_config)["prompts"].startswith("release:")
    rows: dict[str, list[dict]] = {}
    factory = _Factory()

    def send(batch: dict[str, list[dict]]) -> None:
        for table, items in batch.items():
            rows.setdefault(table, []).extend(items)

    runner = EpisodeRunner("w0", "run", factory, send=send, wait=lambda _ref: None)
    outcome = runner.run_unit(unit.work(), 1)
    assert outcome.crash is None and outcome.result is not None
    assert (outcome.result.end_reason, outcome.result.steps) == ("success", 6)
    ours = [[(m.role, m.content) for m in r.messages] for r in factory.clients[0].requests]
    steps = sorted(rows["steps"], key=lambda r: r["index"])
    assert [(s["action"], s["valid"]) for s in steps] == [
        ("search the actor", False),
        (f"search[{ENTITY}]", True),
        ("lookup[Fox]", True),
        *[("look again", False)] * 5,
        ("lookup[Fox]", True),
        ("lookup[Fox]", True),
        ("lookup[Sun]", True),
        ("finish[SUPPORTS]", True),
    ]
    kinds = {m["kind"] for m in rows["messages"] if m["role"] == "user"}
    assert kinds == {
        "release",
        "task",
        "descend",
        "repair",
        "leaf_fail",
        "leaf_done",
        "leaf_judge",
        "nonleaf_done",
        "nonleaf_judge",
        "final_answer",
    }
    observations = [s["observation"] for s in steps if s["valid"]]

    released, actions = _released_requests(monkeypatch, tmp_path, "Claim: " + _claim(claims_dir), observations)
    assert actions == [f"Search[{ENTITY}]", "Lookup[Fox]", "Lookup[Fox]", "Lookup[Fox]", "Lookup[Sun]", "Finish[SUPPORTS]"]
    # the first messages: the framed demonstration (chatbot.py:324-330) and the first prompt (:333-338)
    assert ours[0] == released[0] and len(ours[0]) == 2
    assert str(json.loads((FEVER / "prompts" / "fever_matrix.json").read_text(encoding="utf-8"))) in ours[0][0][1]
    assert len(ours) == len(released) == len(SCRIPT) == 31
    for n, (a, b) in enumerate(zip(ours, released, strict=True), 1):
        assert a == b, f"call {n} differs"
    # the cut (chatbot.py:42-44): the demonstration stays, the task prompt goes first; 32 messages,
    # 33 once an odd error message is in
    assert [len(r) for r in ours[13:]] == [30, 32, 32] + [33] * 15
    assert ours[0][1] in ours[14] and all(r[0] == ours[0][0] and ours[0][1] not in r for r in ours[15:])
    reminded = [n for n, request in enumerate(ours, 1) if config_rules() in request[-1][1] and n > 1]
    assert reminded == [10, 20, 30]  # chatbot.py:352-360 (the rules are in the first prompt too)


def config_rules() -> str:
    return str(tomllib.loads((FEVER / "conf" / "config.toml").read_text(encoding="utf-8-sig"))["rule_description"])


def _claim(claims_dir: Path) -> str:
    for line in (claims_dir / "paper_dev.jsonl").read_text(encoding="utf-8").splitlines():
        row = json.loads(line)
        if row["id"] == 1001:
            return str(row["claim"])
    raise AssertionError("claim 1001 not in the fixture")
