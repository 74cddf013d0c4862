"""The offline test doubles: the expert drives a plan in every style; injection is deterministic;
random and replay answer through litellm like a provider."""

from __future__ import annotations

import asyncio
import json

import pytest

from recap.llm import ChatMessage, LLMError, LLMRequest
from recap.methods import METHODS
from schemas.parts import PartWriter, read_table
from schemas.records import CallRecord, MessageRecord
from workers.gateway.core import DeploymentGateway
from workers.llm.offline.expert import chunk_actions, expert_reply, group_plan
from workers.llm.offline.knobs import INVALID_ACTION, MALFORMED_JSON, Knobs, OfflineOptionsError
from workers.llm.offline.provider import offline_text
from workers.llm.offline.random_model import random_reply
from workers.llm.providers import DeploymentConfig

#: the reply fields each method's agent sends in its hints (the offline models read these, not the name)
FIELDS = {name: agent_cls.reply_fields for name, (agent_cls, _config_cls) in METHODS.items()}
PLAN = ["go to fridge 1", "open fridge 1", "take egg 1 from fridge 1", "go to stove 1", "heat egg 1 with stove 1"]


class ToyEnv:
    """Actions must follow PLAN in order; any plan action is 'valid', a wrong one does nothing."""

    def __init__(self, plan=PLAN):
        self.plan_all = list(plan)
        self.pos = 0
        self.executed: list[str] = []

    def valid(self) -> list[str]:
        return self.plan_all + ["wait"]

    def plan(self) -> list[str]:
        return self.plan_all[self.pos :]

    @property
    def done(self) -> bool:
        return self.pos == len(self.plan_all)

    def step(self, action: str) -> None:
        self.executed.append(action)
        if not self.done and action == self.plan_all[self.pos]:
            self.pos += 1


def drive_recap(env: ToyEnv, knobs: Knobs, max_calls: int = 200) -> list[tuple[str, str, list[str]]]:
    """A minimal ReCAP loop following the call order of recap/recap_agent.py."""
    calls: list[tuple[str, str, list[str]]] = []

    def ask(purpose: str, task: str, depth: int, remaining: list[str]) -> list[str]:
        assert len(calls) < max_calls, "the expert did not finish"
        hints = {
            "style": "recap",
            "purpose": purpose,
            "task": task,
            "depth": depth,
            "remaining": list(remaining),
            "valid_actions": env.valid(),
            "expert_plan": env.plan(),
        }
        reply = expert_reply(hints, knobs, call_key=f"ep#{len(calls)}")
        calls.append((purpose, task, reply["subtasks"]))
        return list(reply["subtasks"])

    def run_child(name: str, depth: int) -> str:
        if name in env.valid():  # shortcut: no call
            env.step(name)
            return "leaf"
        sub = ask("descend", name, depth, [])
        if len(sub) == 1 and sub[0] in env.valid():
            env.step(sub[0])
            return "leaf"
        if len(sub) == 1:
            return "leaf_fail"
        if sub:
            solve(name, depth, sub)
        return "nonleaf"

    def solve(task: str, depth: int, subtasks: list[str]) -> None:
        while subtasks and not env.done:
            kind = run_child(subtasks[0], depth + 1)
            remaining = subtasks[1:]
            if kind == "leaf_fail":
                purpose, remaining = "leaf_fail", subtasks
            else:
                purpose = f"{kind}_done" if remaining else f"{kind}_judge"
            subtasks = ask(purpose, task, depth, remaining)

    goal = "heat an egg"
    solve(goal, 0, ask("task", goal, 0, []))
    return calls


def test_root_reply_groups_the_plan_into_named_chunks():
    assert group_plan(PLAN) == [
        "subgoal 1: go to fridge 1; open fridge 1",
        "subgoal 2: take egg 1 from fridge 1; go to stove 1",
        "heat egg 1 with stove 1",  # a one-action chunk is the action itself (shortcut)
    ]
    assert chunk_actions("subgoal 2: take egg 1 from fridge 1; go to stove 1") == PLAN[2:4]


def test_expert_drives_recap_through_the_protocol_call_order():
    env = ToyEnv()
    calls = drive_recap(env, Knobs())
    assert env.executed == PLAN
    assert [(p, s) for p, _t, s in calls] == [
        ("task", group_plan(PLAN)),
        ("descend", PLAN[0:2]),
        ("leaf_done", PLAN[1:2]),
        ("leaf_judge", []),
        ("nonleaf_done", group_plan(PLAN)[1:]),
        ("descend", PLAN[2:4]),
        ("leaf_done", PLAN[3:4]),
        ("leaf_judge", []),
        ("nonleaf_done", [PLAN[4]]),
        ("leaf_judge", []),
    ]


def test_expert_recovers_from_injected_invalid_actions():
    env = ToyEnv()
    knobs = Knobs(noise_seed=3, invalid_action_rate=0.3)
    calls = drive_recap(env, knobs)
    assert env.done
    assert any(INVALID_ACTION in s for _p, _t, s in calls)
    assert [a for a in env.executed if a != INVALID_ACTION] == PLAN
    assert drive_recap(ToyEnv(), knobs) == calls  # same seed, same run


@pytest.mark.parametrize("style", ["react", "act"])
def test_expert_drives_flat_styles_one_action_per_call(style):
    env = ToyEnv()
    for i in range(20):
        if env.done:
            break
        reply = expert_reply(
            {
                "style": style,
                "reply_fields": FIELDS[style],
                "purpose": "act",
                "expert_plan": env.plan(),
                "valid_actions": env.valid(),
            },
            Knobs(),
            f"ep#{i}",
        )
        assert set(reply) == ({"action"} if style == "act" else {"think", "action"})
        env.step(reply["action"])
    assert env.executed == PLAN


@pytest.mark.parametrize("style,keys", [("cot", {"think", "actions"}), ("standard", {"actions"})])
def test_expert_gives_the_whole_plan_for_open_loop_styles(style, keys):
    reply = expert_reply({"style": style, "reply_fields": FIELDS[style], "purpose": "plan", "expert_plan": PLAN}, Knobs(), "ep#0")
    assert set(reply) == keys and reply["actions"] == PLAN


def test_injection_is_deterministic_per_call_key_and_noise_seed():
    def malformed(seed: int, rate: float, key: str = "noise_seed") -> set[str]:
        out = set()
        for i in range(200):
            meta = {
                "recap_offline": {
                    "call_key": f"ep#{i}",
                    "options": {key: seed, "malformed_json_rate": rate},
                    "hints": {"style": "act", "reply_fields": FIELDS["act"], "expert_plan": PLAN},
                }
            }
            text = offline_text("expert", [{"role": "user", "content": "x"}], meta, None)
            if text == MALFORMED_JSON:
                out.add(f"ep#{i}")
            else:
                assert json.loads(text) == {"action": PLAN[0]}
        return out

    a = malformed(7, 0.5)
    assert a == malformed(7, 0.5)
    assert a != malformed(8, 0.5)
    assert 60 <= len(a) <= 140
    assert malformed(7, 0.0) == set() and len(malformed(7, 1.0)) == 200
    # the option's old name draws the same: run folders written before the rename replay alike
    assert malformed(7, 0.5, key="seed") == a


def test_the_old_seed_option_reads_as_noise_seed_and_both_are_refused():
    assert Knobs.from_options({"seed": 4, "invalid_action_rate": 0.5}) == Knobs(noise_seed=4, invalid_action_rate=0.5)
    assert Knobs.from_options({"noise_seed": 4}) == Knobs(noise_seed=4)
    with pytest.raises(OfflineOptionsError, match=r"^give noise_seed or its old name seed, not both$"):
        Knobs.from_options({"seed": 4, "noise_seed": 4})


def test_random_model_picks_a_valid_action_deterministically():
    valid = ["north", "south", "east", "west"]
    picks = {
        random_reply({"style": "react", "reply_fields": FIELDS["react"], "valid_actions": valid}, Knobs(noise_seed=1), f"k{i}")[
            "action"
        ]
        for i in range(40)
    }
    assert picks == set(valid)
    one = random_reply({"style": "recap", "valid_actions": valid}, Knobs(noise_seed=1), "k0")
    assert one == random_reply({"style": "recap", "valid_actions": valid}, Knobs(noise_seed=1), "k0")
    assert len(one["subtasks"]) == 1 and one["subtasks"][0] in valid


def _request(i: int, text: str, hints=None, episode: str = "ep") -> LLMRequest:
    return LLMRequest(
        messages=(ChatMessage("user", text),),
        episode_id=episode,
        call_index=i,
        purpose="task",
        window_seqs=(0,),
        response_seq=1,
        hints=hints or {},
    )


def test_offline_expert_takes_the_provider_path_and_is_labelled_a_test_double(run_dir):
    cfg = DeploymentConfig(model="offline/expert", offline_options={"seed": 1})

    async def go():
        gw = DeploymentGateway(cfg, run_dir=run_dir, run_id="r")
        hints = {"style": "react", "reply_fields": FIELDS["react"], "purpose": "act", "expert_plan": PLAN}
        resp = await gw.complete(_request(0, "what next?", hints))
        await gw.aclose()
        return resp

    resp = asyncio.run(go())
    assert json.loads(resp.text) == {"think": "Expert plan: 5 action(s) left.", "action": PLAN[0]}
    assert resp.test_double and resp.model == "offline/expert" and resp.token_count_source == "provider"
    # nominal test-double price: $1/M input, $2/M output
    assert resp.cost_usd == (resp.prompt_tokens * 1 + resp.completion_tokens * 2) / 1e6
    rows = read_table(run_dir, "llm_calls")[0].to_pylist()
    assert [(r["model"], r["test_double"], r["status"]) for r in rows] == [("offline/expert", True, "ok")]


def test_replay_serves_recorded_responses_by_message_hash(tmp_path, run_dir):
    old = tmp_path / "old-run"
    PartWriter(old).write_records(
        "old",
        [
            MessageRecord("e1", 0, "user", "task", "make tea"),
            MessageRecord("e1", 1, "assistant", "reply", '{"think": "t", "subtasks": ["boil water"]}'),
            CallRecord("e1", 0, "e1#0", "task", (0,), "openai/gpt-4o", "ok", response_seq=1),
        ],
    )
    cfg = DeploymentConfig(model="offline/replay", api_base=str(old))

    async def go():
        gw = DeploymentGateway(cfg, run_dir=run_dir, run_id="r")
        hit = await gw.complete(_request(0, "make tea", episode="new"))
        with pytest.raises(LLMError) as miss:
            await gw.complete(_request(1, "make coffee", episode="new"))
        await gw.aclose()
        return hit, miss.value

    hit, miss = asyncio.run(go())
    assert hit.text == '{"think": "t", "subtasks": ["boil water"]}'
    assert (hit.served_from, hit.cost_usd, hit.test_double) == ("replay", 0.0, True)
    assert miss.kind == "bad_request" and "no recorded response" in miss.message
