"""What each method declares on its agent class (reply fields, estimate assumptions), the method
registry, and the offline test doubles answering from the declared reply fields alone."""

from __future__ import annotations

import pytest

import workers.agents  # noqa: F401  (registers the workers' method, mini_swe: the registry's full list, in every process)
from recap.agent import Agent
from recap.baselines import ADaPTAgent, ReActAgent, ReActConfig
from recap.config import AgentConfig, ConfigError, ReCAPConfig
from recap.methods import METHODS, method_classes, register_method, registered_method, unregister_method
from tests.recap.baseline_harness import DEMO_ACTIONS, run_agent
from workers.llm.offline.expert import expert_reply
from workers.llm.offline.knobs import INVALID_ACTION, Knobs
from workers.llm.offline.random_model import random_reply

PLAN = ["pick up B", "stack B on A"]


def test_the_registry_names_the_built_in_methods_in_order():
    # the six of recap/method_registry.py, then mini_swe (registered by workers/agents)
    assert tuple(METHODS) == ("recap", "react", "act", "cot", "standard", "adapt", "mini_swe")
    for name, (agent_cls, _config_cls) in METHODS.items():
        assert agent_cls.style == name


def test_each_method_declares_its_reply_fields():
    assert {name: agent_cls.reply_fields for name, (agent_cls, _c) in METHODS.items()} == {
        "recap": ("think", "subtasks"),
        "react": ("think", "action"),
        "act": ("action",),
        "cot": ("think", "actions"),
        "standard": ("actions",),
        "adapt": ("think", "action"),
        "mini_swe": ("think", "action"),
    }


def test_the_estimate_asks_the_agent_class():
    from pipeline.estimate import call_shape

    # the values the estimate used to keep in its own table, per method name
    assert {name: call_shape(name) for name in METHODS} == {
        "recap": (False, (1.0, 2.5)),
        "react": (False, (1.0, 1.0)),
        "act": (False, (1.0, 1.0)),
        "cot": (True, (1.0, 2.5)),
        "standard": (True, (1.0, 2.5)),
        "adapt": (False, (1.0, 3.0)),
        "mini_swe": (False, (1.0, 1.0)),
    }
    assert call_shape("no_such_method") == (False, (1.0, 2.5))


def test_adapt_planner_contexts_ask_for_subtasks_repairs_included():
    failed = {"think": "too much at once", "status": "failed"}
    split = {"think": "split", "subtasks": ["clear block A", "build the tower"], "logic": "and"}
    react = [{"think": "t", "action": a} for a in DEMO_ACTIONS]
    done = {"think": "done", "status": "done"}
    run = run_agent(ADaPTAgent(), [failed, "not json", split, *react[:2], done, *react[2:]])
    assert run.result.end_reason == "success" and run.result.json_repairs == 1
    assert [(r.purpose, r.hints["reply_fields"]) for r in run.client.requests[:5]] == [
        ("executor_task", ("think", "action")),
        ("planner_task", ("think", "subtasks")),
        ("repair", ("think", "subtasks")),  # the planner's own context: its repair asks for subtasks
        ("executor_task", ("think", "action")),
        ("observation", ("think", "action")),
    ]


class _Probe(ReActAgent):
    style = "probe"


def test_register_and_unregister_a_method():
    assert "probe" not in METHODS
    with registered_method("probe", _Probe, ReActConfig):
        assert method_classes("probe") == (_Probe, ReActConfig)
        with pytest.raises(ConfigError, match="'probe' is already registered"):
            register_method("probe", _Probe, ReActConfig)
    assert "probe" not in METHODS
    with pytest.raises(ConfigError, match="unknown method 'probe'"):
        method_classes("probe")
    with pytest.raises(ConfigError, match="'probe' is not registered"):
        unregister_method("probe")
    with pytest.raises(RuntimeError, match="boom"), registered_method("probe", _Probe, ReActConfig):
        raise RuntimeError("boom")
    assert "probe" not in METHODS


@pytest.mark.parametrize(
    "name,agent_cls,config_cls,message",
    [
        ("other", _Probe, ReActConfig, r"_Probe.style must be 'other'"),
        ("probe", dict, ReActConfig, "is not an Agent subclass"),
        ("probe", _Probe, ReCAPConfig, "is not a ReActConfig"),
        ("probe", _Probe, AgentConfig, "is not a ReActConfig"),
    ],
)
def test_registration_checks_the_classes(name, agent_cls, config_cls, message):
    with pytest.raises(ConfigError, match=message):
        register_method(name, agent_cls, config_cls)
    assert name not in METHODS


# -- the offline test doubles fill whatever fields the agent declares ------------------------------


@pytest.mark.parametrize(
    "fields,reply",
    [
        (("think", "subtasks"), {"think": "Expert plan: 2 action(s) left.", "subtasks": PLAN}),
        (("think", "action"), {"think": "Expert plan: 2 action(s) left.", "action": "pick up B"}),
        (("action",), {"action": "pick up B"}),
        (("think", "actions"), {"think": "Expert plan: 2 action(s) left.", "actions": PLAN}),
        (("actions",), {"actions": PLAN}),
        (("actions", "think"), {"actions": PLAN, "think": "Expert plan: 2 action(s) left."}),
    ],
)
def test_the_expert_fills_the_declared_fields_in_order(fields, reply):
    got = expert_reply({"purpose": "task", "reply_fields": fields, "expert_plan": PLAN}, Knobs(), "ep#0")
    assert got == reply and list(got) == list(reply)


def test_the_method_name_does_not_change_the_reply():
    hints = {"purpose": "task", "expert_plan": PLAN, "valid_actions": PLAN}
    for style in (*METHODS, "anything"):
        assert expert_reply({**hints, "style": style, "reply_fields": ["action"]}, Knobs(), "k") == {"action": "pick up B"}
        assert random_reply({**hints, "style": style, "reply_fields": ["actions"]}, Knobs(noise_seed=2), "k") == {
            "actions": ["stack B on A"]
        }
    # no fields named: a decomposition, as a request without hints always got
    assert expert_reply({**hints, "style": "act"}, Knobs(), "k") == {"think": "Expert plan: 2 action(s) left.", "subtasks": PLAN}


def test_injection_and_unknown_fields():
    knobs = Knobs(noise_seed=1, invalid_action_rate=1.0)
    hints = {"purpose": "task", "expert_plan": PLAN}
    assert expert_reply({**hints, "reply_fields": ("action",)}, knobs, "k") == {"action": INVALID_ACTION}
    assert expert_reply({**hints, "reply_fields": ("actions",)}, knobs, "k") == {"actions": [INVALID_ACTION, "stack B on A"]}
    with pytest.raises(ValueError, match="offline/expert: cannot fill reply field 'status'"):
        expert_reply({**hints, "reply_fields": ("think", "status")}, Knobs(), "k")
    with pytest.raises(ValueError, match="offline/random: cannot fill reply field 'logic'"):
        random_reply({**hints, "reply_fields": ("logic",)}, Knobs(), "k")


def test_an_agent_class_without_its_own_declarations_gets_the_base_ones():
    class Bare(Agent):
        style = "bare"
        expected_format = "{}"

        def play(self, ep, reset):
            return None

    assert (Bare.reply_fields, Bare.one_shot, Bare.estimate_calls_per_step) == (("think", "subtasks"), False, (1.0, 2.5))
    assert Bare.demo_replies(None) is None  # type: ignore[arg-type]
