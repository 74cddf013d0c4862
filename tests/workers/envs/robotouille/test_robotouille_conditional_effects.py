"""Taking an item (or pot) off its station while a timed conditional effect runs, and putting it back.

Rule (see ``workers/envs/robotouille/effects.py``): while a conditional effect's conditions fail, each
update sets its own effects to their negation and leaves its nested effects alone (the timer does not
tick); the effect stays registered, so once the conditions hold again its effects come back and the
timer continues from where it stopped (a pause: no restart, no completion).

T7 (real engine) pins this for cook; a small made-up kitchen domain, written out here, exercises every
conditional effect kind of the benchmark domain (cook, fry, fill pot, boil) plus a conditional whose own
effect is a negative literal, the repetitive cut and re-issued actions.
"""

from __future__ import annotations

import json

import pytest

from workers.envs.robotouille.domain import load_domain, parse_domain
from workers.envs.robotouille.problem import build_problem
from workers.envs.robotouille.replay import replay_file

from .helpers import DATA, require_data

T7 = "T7_sync_0_cheese_sandwich_seed126_pickup_while_cooking.json"


# ------------------------------------------------------------------------------------------ T7
def test_t7_replays_identically():
    assert replay_file(str(require_data() / "trajectories" / T7)) == (True, "45 steps identical")


def test_t7_pickup_while_cooking_undoes_cooking_and_pauses_the_timer():
    """Cook at 24; off the stove at 25-26 (not cooking, timer held at 1); back at 27; cooked after 29."""
    record = json.loads((require_data() / "trajectories" / T7).read_text())
    problem = build_problem(load_domain(DATA), record["generated_environment_json"])
    state = problem.state
    seen = {}
    for t, step in enumerate(record["steps"], start=1):
        state.apply(next(g for g in state.valid_groundings() if g.text == step["action"]))
        if 24 <= t <= 29:
            assert state.observation(problem.goal_description) == step["observation"], t
            assert list(state.valid_actions()) == step["valid_actions"], t
            timers = [e.nested[0].counter for e in state.effects if e.arg == "patty1"]
            seen[t] = (
                state.is_true("iscooking", "patty1"),
                state.is_true("iscooked", "patty1"),
                state.is_true("has_item", "robot1", "patty1"),
                timers,
            )
    assert seen == {
        24: (True, False, False, [1]),
        25: (False, False, True, [1]),  # picked up: undone, no tick
        26: (False, False, True, [1]),  # still off the stove: paused
        27: (True, False, False, [2]),  # put back: cooking again, the timer goes on from 1
        28: (True, False, False, [3]),
        29: (False, True, False, []),  # cooked two steps late; the effect is dropped
    }
    step25 = record["steps"][24]["observation"]
    assert "patty1 is held by robot1" in step25 and "patty1 is cooking" not in step25


# ------------------------------------------------------------------------- the made-up kitchen
def _lit(pred, *params, is_true=True):
    return {"predicate": pred, "params": list(params), "is_true": is_true}


def _delayed(param, fx, sfx=()):
    return {"type": "delayed", "param": param, "fx": list(fx), "sfx": list(sfx)}


def _conditional(param, conditions, fx, sfx):
    return {"type": "conditional", "param": param, "conditions": list(conditions), "fx": list(fx), "sfx": list(sfx)}


_PREDICATES = [
    ("isstove", ["station"], "{0} is a stove"),
    ("isfryer", ["station"], "{0} is a fryer"),
    ("issink", ["station"], "{0} is a sink"),
    ("isboard", ["station"], "{0} is a board"),
    ("ispatty", ["item"], "{0} is a patty"),
    ("ischicken", ["item"], "{0} is chicken"),
    ("isfish", ["item"], "{0} is fish"),
    ("isonion", ["item"], "{0} is an onion"),
    ("isrobot", ["player"], "{0} is a robot"),
    ("ispot", ["container"], "{0} is a pot"),
    ("iswater", ["meal"], "{0} is water"),
    ("iscookable", ["item"], "{0} is cookable"),
    ("iscooking", ["item"], "{0} is cooking"),
    ("iscooked", ["item"], "{0} is cooked"),
    ("isfryable", ["item"], "{0} is fryable"),
    ("isfried", ["item"], "{0} is fried"),
    ("isfrozen", ["item"], "{0} is frozen"),
    ("isthawed", ["item"], "{0} is thawed"),
    ("iscuttable", ["item"], "{0} is cuttable"),
    ("iscut", ["item"], "{0} is cut"),
    ("isboiling", ["meal"], "{0} is boiling"),
    ("loc", ["player", "station"], ("{0} is at {1}", "{1} has {0} at it")),
    ("vacant", ["station"], "{0} is vacant"),
    ("nothing", ["player"], "{0} holds nothing"),
    ("station_empty", ["station"], "{0} is empty"),
    ("container_empty", ["container"], "{0} is empty"),
    ("item_on", ["item", "station"], ("{0} is on {1}", "{1} holds {0}")),
    ("item_at", ["item", "station"], ("{0} is at {1}", "{1} has {0}")),
    ("clear", ["item"], "{0} is clear"),
    ("atop", ["item", "item"], ("{0} is atop {1}", "{1} is under {0}")),
    ("has_item", ["player", "item"], ("{0} holds {1}", "{1} is held by {0}")),
    ("has_container", ["player", "container"], ("{0} holds {1}", "{1} is held by {0}")),
    ("container_at", ["container", "station"], ("{0} is at {1}", "{1} has {0}")),
    ("in", ["meal", "container"], ("{0} is in {1}", "{1} contains {0}")),
]


def _action(name, description, precons, fx=(), sfx=()):
    return {
        "name": name,
        "precons": list(precons),
        "immediate_fx": list(fx),
        "sfx": list(sfx),
        "language_description": description,
    }


def mini_domain():
    """A small kitchen domain: moving, carrying, and one timed conditional action per station kind."""
    preds = []
    for name, types, sentences in _PREDICATES:
        if isinstance(sentences, str):
            sentences = (sentences,)
        preds.append({"name": name, "param_types": types, "language_descriptors": {str(k): s for k, s in enumerate(sentences)}})
    at = [_lit("loc", "p1", "s1")]
    hands_free = [_lit("nothing", "p1")]
    actions = [
        _action(
            "move",
            "Move {p1} from {s1} to {s2}",
            at + [_lit("vacant", "s2")],
            [
                _lit("loc", "p1", "s2"),
                _lit("loc", "p1", "s1", is_true=False),
                _lit("vacant", "s1"),
                _lit("vacant", "s2", is_true=False),
            ],
        ),
        _action(
            "pick-up-item",
            "Pick up {i1} from {s1} using {p1}",
            hands_free + [_lit("item_on", "i1", "s1")] + at + [_lit("clear", "i1")],
            [
                _lit("has_item", "p1", "i1"),
                _lit("station_empty", "s1"),
                _lit("nothing", "p1", is_true=False),
                _lit("item_at", "i1", "s1", is_true=False),
                _lit("clear", "i1", is_true=False),
                _lit("item_on", "i1", "s1", is_true=False),
            ],
        ),
        _action(
            "place-item",
            "Place {i1} on {s1} using {p1}",
            [_lit("has_item", "p1", "i1")] + at + [_lit("station_empty", "s1")],
            [
                _lit("nothing", "p1"),
                _lit("item_at", "i1", "s1"),
                _lit("clear", "i1"),
                _lit("item_on", "i1", "s1"),
                _lit("has_item", "p1", "i1", is_true=False),
                _lit("station_empty", "s1", is_true=False),
            ],
        ),
        _action(
            "pick-up-container",
            "Pick up {c1} from {s1} using {p1}",
            hands_free + [_lit("container_at", "c1", "s1")] + at,
            [
                _lit("has_container", "p1", "c1"),
                _lit("container_at", "c1", "s1", is_true=False),
                _lit("nothing", "p1", is_true=False),
                _lit("station_empty", "s1"),
            ],
        ),
        _action(
            "place-container",
            "Place {c1} on {s1} using {p1}",
            [_lit("has_container", "p1", "c1")] + at + [_lit("station_empty", "s1")],
            [
                _lit("nothing", "p1"),
                _lit("container_at", "c1", "s1"),
                _lit("has_container", "p1", "c1", is_true=False),
                _lit("station_empty", "s1", is_true=False),
            ],
        ),
        _action(
            "cook",
            "Cook {i1} on {s1} using {p1}",
            [_lit("isstove", "s1"), _lit("iscookable", "i1"), _lit("iscooking", "i1", is_true=False), _lit("item_on", "i1", "s1")]
            + at
            + hands_free,
            sfx=[
                _conditional(
                    "i1",
                    [_lit("item_on", "i1", "s1")],
                    [_lit("iscooking", "i1")],
                    [_delayed("i1", [_lit("iscooked", "i1"), _lit("iscooking", "i1", is_true=False)])],
                )
            ],
        ),
        _action(
            "fry",
            "Fry {i1} on {s1} using {p1}",
            [_lit("isfryer", "s1"), _lit("isfryable", "i1"), _lit("item_on", "i1", "s1")] + at + hands_free,
            sfx=[_conditional("i1", [_lit("item_on", "i1", "s1")], [], [_delayed("i1", [_lit("isfried", "i1")])])],
        ),
        _action(
            "thaw",
            "Thaw {i1} in {s1} using {p1}",
            [_lit("issink", "s1"), _lit("isfrozen", "i1"), _lit("item_on", "i1", "s1")] + at + hands_free,
            sfx=[
                _conditional(
                    "i1",
                    [_lit("item_on", "i1", "s1")],
                    [_lit("isfrozen", "i1", is_true=False)],
                    [_delayed("i1", [_lit("isthawed", "i1")])],
                )
            ],
        ),
        _action(
            "cut",
            "Cut {i1} on {s1} using {p1}",
            [_lit("isboard", "s1"), _lit("iscuttable", "i1"), _lit("item_on", "i1", "s1")] + at + hands_free,
            sfx=[{"type": "repetitive", "param": "i1", "fx": [_lit("iscut", "i1")], "sfx": []}],
        ),
        _action(
            "fill-pot",
            "Fill {c1} with water from {s1} using {p1}",
            [_lit("ispot", "c1"), _lit("issink", "s1")]
            + at
            + [_lit("container_at", "c1", "s1"), _lit("container_empty", "c1")]
            + hands_free,
            sfx=[
                _conditional(
                    "c1",
                    [_lit("container_at", "c1", "s1")],
                    [],
                    [
                        _delayed(
                            "c1",
                            [],
                            [
                                {
                                    "type": "creation",
                                    "param": "c1",
                                    "created_obj": {"name": "water", "type": "meal", "param": "m1"},
                                    "fx": [
                                        _lit("iswater", "m1"),
                                        _lit("in", "m1", "c1"),
                                        _lit("container_empty", "c1", is_true=False),
                                    ],
                                    "sfx": [],
                                }
                            ],
                        )
                    ],
                )
            ],
        ),
        _action(
            "boil-water",
            "Boil {c1}'s contents on {s1} using {p1}",
            [
                _lit("ispot", "c1"),
                _lit("iswater", "m1"),
                _lit("in", "m1", "c1"),
                _lit("isstove", "s1"),
                _lit("container_at", "c1", "s1"),
            ]
            + at
            + hands_free,
            sfx=[_conditional("m1", [_lit("container_at", "c1", "s1")], [], [_delayed("m1", [_lit("isboiling", "m1")])])],
        ),
        _action("wait", "Do nothing", []),
    ]
    return parse_domain(
        {
            "name": "mini",
            "object_types": ["station", "item", "player", "container", "meal"],
            "predicate_defs": preds,
            "action_defs": actions,
        }
    )


def kitchen(stations, items=(), containers=(), meals=(), time=3):
    """Stations in a row at y=1 (x = 0, 1, ...); the robot stands in front of the first one."""
    return {
        "config": {"cook_time": {"default": time}, "num_cuts": {"default": 3}},
        "stations": [{"name": name, "x": x, "y": 1} for x, name in enumerate(stations)],
        "items": [{"name": name, "x": x, "y": 1, "stack-level": 0, "predicates": list(preds)} for name, x, preds in items],
        "containers": [{"name": name, "x": x, "y": 1} for name, x in containers],
        "meals": [{"name": name, "x": x, "y": 1} for name, x in meals],
        "players": [{"name": "robot", "x": 0, "y": 0, "direction": [0, 1]}],
        "goal_description": "Test goal",
        "goal": [{"predicate": "nothing", "args": ["robot"], "ids": [1], "is_true": False}],
    }


def start(problem_json):
    problem = build_problem(mini_domain(), problem_json, "mini kitchen")
    return problem.state


def act(state, text):
    grounding = next((g for g in state.valid_groundings() if g.text == text), None)
    assert grounding is not None, f"{text!r} not in {state.valid_actions()}"
    state.apply(grounding)


def timers(state):
    """(kind of the outer effect, counter of its nested timer) for every effect in flight."""
    return [(e.spec.kind, e.nested[0].counter if e.nested else e.counter) for e in state.effects]


# one case per conditional effect kind of the benchmark domain, plus one whose own effect is negative:
# kitchen, start action, take-away action, put-back action, the fact its timer sets, and the
# conditional's own effect with its truth after each step of SCRIPT (None: it has no own effect)
CASES = {
    "cook": (
        kitchen(["stove"], items=[("patty", 0, ["iscookable"])]),
        "Cook patty1 on stove1 using robot1",
        "Pick up patty1 from stove1 using robot1",
        "Place patty1 on stove1 using robot1",
        ("iscooked", "patty1"),
        (("iscooking", "patty1"), [True, True, False, False, True, False]),
    ),
    "fry": (
        kitchen(["fryer"], items=[("chicken", 0, ["isfryable"])]),
        "Fry chicken1 on fryer1 using robot1",
        "Pick up chicken1 from fryer1 using robot1",
        "Place chicken1 on fryer1 using robot1",
        ("isfried", "chicken1"),
        None,
    ),
    "fill": (
        kitchen(["sink"], containers=[("pot", 0)]),
        "Fill pot1 with water from sink1 using robot1",
        "Pick up pot1 from sink1 using robot1",
        "Place pot1 on sink1 using robot1",
        ("iswater", "water1"),
        None,
    ),
    "boil": (
        kitchen(["stove"], containers=[("pot", 0)], meals=[("water", 0)]),
        "Boil pot1's contents on stove1 using robot1",
        "Pick up pot1 from stove1 using robot1",
        "Place pot1 on stove1 using robot1",
        ("isboiling", "water1"),
        None,
    ),
    # fx "not isfrozen": taking the fish out of the sink makes it frozen again until it is put back
    "thaw": (
        kitchen(["sink"], items=[("fish", 0, ["isfrozen"])]),
        "Thaw fish1 in sink1 using robot1",
        "Pick up fish1 from sink1 using robot1",
        "Place fish1 on sink1 using robot1",
        ("isthawed", "fish1"),
        (("isfrozen", "fish1"), [False, False, True, True, False, False]),
    ),
}


def _fact(state, fact):
    pred, obj = fact
    return obj in state.types and state.is_true(pred, obj)


@pytest.mark.parametrize("kind", sorted(CASES))
def test_untouched_timer_fires_three_steps_after_the_action(kind):
    problem_json, start_action, _, _, done_fact, _ = CASES[kind]
    state = start(problem_json)
    act(state, start_action)
    for _ in range(2):
        act(state, "Do nothing")
        assert not _fact(state, done_fact)
    act(state, "Do nothing")
    assert _fact(state, done_fact)
    assert state.effects == []


@pytest.mark.parametrize("kind", sorted(CASES))
def test_take_away_undoes_and_pauses_put_back_resumes_where_it_stopped(kind):
    problem_json, start_action, take, put_back, done_fact, own = CASES[kind]
    state = start(problem_json)
    script = [start_action, "Do nothing", take, "Do nothing", put_back, "Do nothing"]
    log = []
    for action in script:
        act(state, action)
        log.append((timers(state), _fact(state, done_fact), None if own is None else _fact(state, own[0])))
    own_trace = [None] * len(script) if own is None else own[1]
    assert log == [
        ([("conditional", 1)], False, own_trace[0]),  # the action's own step is the first tick
        ([("conditional", 2)], False, own_trace[1]),
        ([("conditional", 2)], False, own_trace[2]),  # taken away: own effect negated, no tick
        ([("conditional", 2)], False, own_trace[3]),  # still away: paused, negated again
        ([("conditional", 3)], False, own_trace[4]),  # put back: own effect again, timer goes on
        ([], True, own_trace[5]),  # fires two steps late; nothing restarted
    ]


def test_cook_take_away_and_put_back_exact_observations():
    state = start(CASES["cook"][0])
    goal = "Test goal"
    act(state, "Cook patty1 on stove1 using robot1")
    assert state.observation(goal) == "\n".join(
        [
            "Station stove1:",
            "stove1 is a stove",
            "stove1 has robot1 at it",
            "stove1 holds patty1",
            "stove1 has patty1",
            "",
            "Item patty1:",
            "patty1 is a patty",
            "patty1 is cookable",
            "patty1 is cooking",
            "patty1 is on stove1",
            "patty1 is at stove1",
            "patty1 is clear",
            "",
            "Player robot1:",
            "robot1 is a robot",
            "robot1 is at stove1",
            "robot1 holds nothing",
            "",
            "Valid Actions:",
            "Pick up patty1 from stove1 using robot1",
            "Do nothing",
            "",
            "Goal: Test goal",
        ]
    )
    act(state, "Pick up patty1 from stove1 using robot1")
    held = "\n".join(
        [
            "Station stove1:",
            "stove1 is a stove",
            "stove1 has robot1 at it",
            "stove1 is empty",
            "",
            "Item patty1:",
            "patty1 is a patty",
            "patty1 is cookable",
            "patty1 is held by robot1",
            "",
            "Player robot1:",
            "robot1 is a robot",
            "robot1 is at stove1",
            "robot1 holds patty1",
            "",
            "Valid Actions:",
            "Place patty1 on stove1 using robot1",
            "Do nothing",
            "",
            "Goal: Test goal",
        ]
    )
    assert state.observation(goal) == held
    act(state, "Do nothing")
    assert state.observation(goal) == held
    act(state, "Place patty1 on stove1 using robot1")
    # cooking again at once, so Cook is not offered (its precondition wants "not cooking")
    assert "patty1 is cooking" in state.observation(goal)
    assert state.valid_actions() == ("Pick up patty1 from stove1 using robot1", "Do nothing")
    act(state, "Do nothing")
    assert not state.is_true("iscooked", "patty1")
    act(state, "Do nothing")
    obs = state.observation(goal)
    assert "patty1 is cooked" in obs and "patty1 is cooking" not in obs
    # not cooking any more: Cook is offered again (the domain has no "not cooked" precondition)
    assert state.valid_actions() == (
        "Pick up patty1 from stove1 using robot1",
        "Cook patty1 on stove1 using robot1",
        "Do nothing",
    )


def test_fill_pot_taken_off_the_sink_creates_its_water_two_steps_late():
    state = start(CASES["fill"][0])
    act(state, "Fill pot1 with water from sink1 using robot1")
    act(state, "Pick up pot1 from sink1 using robot1")
    for _ in range(3):
        act(state, "Do nothing")
    assert state.objects["meal"] == [] and timers(state) == [("conditional", 1)]
    act(state, "Place pot1 on sink1 using robot1")
    act(state, "Do nothing")
    assert state.objects["meal"] == []
    # while the pot is empty Fill stays valid; re-issuing it advances nothing (delayed ticks passively)
    act(state, "Fill pot1 with water from sink1 using robot1")
    assert state.objects["meal"] == ["water1"] and state.effects == []
    assert state.observation("g").split("\n\nValid Actions:")[0].split("\n\n")[-2:] == [
        "Container pot1:\npot1 is a pot\npot1 is at sink1\npot1 contains water1",
        "Meal water1:\nwater1 is water\nwater1 is in pot1",
    ]


def test_reissuing_the_action_after_put_back_reuses_the_paused_effect():
    """Fry has no "not frying" precondition: frying again continues the registered timer."""
    state = start(CASES["fry"][0])
    act(state, "Fry chicken1 on fryer1 using robot1")  # 1
    act(state, "Pick up chicken1 from fryer1 using robot1")  # paused at 1
    act(state, "Place chicken1 on fryer1 using robot1")  # 2
    act(state, "Fry chicken1 on fryer1 using robot1")  # same effect: 3, not a new one at 1
    assert timers(state) == [("conditional", 3)]
    act(state, "Do nothing")
    assert state.is_true("isfried", "chicken1") and state.effects == []


def test_cooking_on_another_stove_starts_a_new_timer_and_leaves_the_first_paused():
    state = start(kitchen(["stove", "stove"], items=[("patty", 0, ["iscookable"])]))
    act(state, "Cook patty1 on stove1 using robot1")  # first timer 1
    act(state, "Do nothing")  # 2
    act(state, "Pick up patty1 from stove1 using robot1")
    act(state, "Move robot1 from stove1 to stove2")
    act(state, "Place patty1 on stove2 using robot1")
    assert not state.is_true("iscooking", "patty1")  # the first effect is not met there
    assert "Cook patty1 on stove2 using robot1" in state.valid_actions()
    act(state, "Cook patty1 on stove2 using robot1")
    # a second effect (its conditions name stove2) from zero; the first stays registered, paused at 2
    assert timers(state) == [("conditional", 2), ("conditional", 1)]
    assert state.is_true("iscooking", "patty1")  # the newer effect updates last
    for _ in range(2):
        act(state, "Do nothing")
    assert not state.is_true("iscooked", "patty1")
    act(state, "Do nothing")
    assert state.is_true("iscooked", "patty1") and not state.is_true("iscooking", "patty1")
    assert timers(state) == [("conditional", 2)]
    # the old one resumes if the patty goes back to its first stove
    act(state, "Pick up patty1 from stove2 using robot1")
    act(state, "Move robot1 from stove2 to stove1")
    act(state, "Place patty1 on stove1 using robot1")
    assert timers(state) == [("conditional", 3)] and state.is_true("iscooking", "patty1")
    act(state, "Do nothing")
    assert state.effects == [] and not state.is_true("iscooking", "patty1")
    assert state.is_true("iscooked", "patty1")


def test_completed_effect_is_not_undone_by_taking_the_item_away():
    state = start(CASES["cook"][0])
    act(state, "Cook patty1 on stove1 using robot1")
    for _ in range(3):
        act(state, "Do nothing")
    act(state, "Pick up patty1 from stove1 using robot1")
    assert state.is_true("iscooked", "patty1") and not state.is_true("iscooking", "patty1")
    assert state.effects == []


def test_cut_count_survives_taking_the_item_off_the_board():
    """Repetitive effects are not conditional: the 3rd cut of the item fires, whatever happens between."""
    state = start(kitchen(["board", "board"], items=[("onion", 0, ["iscuttable"])]))
    act(state, "Cut onion1 on board1 using robot1")
    act(state, "Pick up onion1 from board1 using robot1")
    act(state, "Do nothing")
    assert [(e.spec.kind, e.counter) for e in state.effects] == [("repetitive", 1)]
    act(state, "Move robot1 from board1 to board2")
    act(state, "Place onion1 on board2 using robot1")
    act(state, "Cut onion1 on board2 using robot1")
    assert not state.is_true("iscut", "onion1")
    act(state, "Cut onion1 on board2 using robot1")
    assert state.is_true("iscut", "onion1") and state.effects == []


def test_a_clone_keeps_the_paused_timer_apart_from_the_original():
    state = start(CASES["cook"][0])
    act(state, "Cook patty1 on stove1 using robot1")
    act(state, "Pick up patty1 from stove1 using robot1")
    copy = state.clone()
    act(copy, "Place patty1 on stove1 using robot1")
    assert timers(copy) == [("conditional", 2)] and copy.is_true("iscooking", "patty1")
    assert timers(state) == [("conditional", 1)] and not state.is_true("iscooking", "patty1")
