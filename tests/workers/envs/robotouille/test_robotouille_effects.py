"""Special effects the benchmark domain does not exercise (immediate, deletion) and object creation.

The real domain is extended in memory with two made-up actions so that every effect kind of the
interpreter runs; the benchmark behaviour itself is pinned by the trajectory replays.
"""

from __future__ import annotations

import copy
import json

from workers.envs.robotouille.domain import parse_domain
from workers.envs.robotouille.problem import build_problem

from .helpers import DATA, instance_record, require_data


def _domain_with_extras():
    raw = copy.deepcopy(json.loads((require_data() / "domain" / "robotouille.json").read_text()))
    raw["action_defs"].insert(
        0,
        {
            "name": "discard",
            "precons": [
                {"predicate": "has_item", "params": ["p1", "i1"], "is_true": True},
                {"predicate": "loc", "params": ["p1", "s1"], "is_true": True},
                {"predicate": "issink", "params": ["s1"], "is_true": True},
            ],
            "immediate_fx": [
                {"predicate": "has_item", "params": ["p1", "i1"], "is_true": False},
                {"predicate": "nothing", "params": ["p1"], "is_true": True},
            ],
            "sfx": [{"type": "deletion", "param": "i1", "fx": [], "sfx": []}],
            "language_description": "Throw {i1} away at {s1} using {p1}",
        },
    )
    raw["action_defs"].insert(
        0,
        {
            "name": "chop",
            "precons": [
                {"predicate": "item_on", "params": ["i1", "s1"], "is_true": True},
                {"predicate": "loc", "params": ["p1", "s1"], "is_true": True},
                {"predicate": "iscut", "params": ["i1"], "is_true": False},
            ],
            "immediate_fx": [],
            "sfx": [
                {"type": "immediate", "param": "i1", "fx": [{"predicate": "iscut", "params": ["i1"], "is_true": True}], "sfx": []}
            ],
            "language_description": "Chop {i1} at once on {s1} using {p1}",
        },
    )
    return parse_domain(raw)


def _apply(state, text):
    state.apply(next(g for g in state.valid_groundings() if g.text == text))


def test_immediate_effect_applies_in_the_same_step_and_leaves_no_trace():
    domain = _domain_with_extras()
    record = instance_record("synchronous", "0_cheese_sandwich", 42)
    problem = build_problem(domain, record["generated_environment_json"])
    state = problem.state
    assert state.valid_actions()[0] == "Chop cheese1 at once on table1 using robot1"
    _apply(state, "Chop cheese1 at once on table1 using robot1")
    assert state.is_true("iscut", "cheese1")
    assert state.effects == []
    assert "Chop" not in " ".join(state.valid_actions())


def test_deletion_removes_the_object_everywhere():
    domain = _domain_with_extras()
    record = instance_record("synchronous", "0_cheese_sandwich", 42)
    state = build_problem(domain, record["generated_environment_json"]).state
    for action in [
        "Pick up cheese1 from table1 using robot1",
        "Move robot1 from table1 to sink1",
        "Throw cheese1 away at sink1 using robot1",
    ]:
        _apply(state, action)
    assert "cheese1" not in state.types and "cheese1" not in state.objects["item"]
    assert not any("cheese1" in row for _, row in state.true_facts())
    assert "cheese1" not in state.observation("g")
    assert state.is_true("nothing", "robot1")
    # indexes of the remaining items follow their naming order again
    assert [state.index[i] for i in state.objects["item"]] == list(range(len(state.objects["item"])))


def test_created_objects_are_numbered_per_name():
    record = instance_record("asynchronous", "5_potato_soup", 42)
    from workers.envs.robotouille.domain import load_domain

    state = build_problem(load_domain(DATA), record["generated_environment_json"]).state
    assert state.create_object("water", "meal") == "water1"
    assert state.create_object("water", "meal") == "water2"
    assert state.objects["meal"] == ["water1", "water2"]
    assert state.observation("g").split("Valid Actions:")[0].rstrip().endswith("Meal water2:")
