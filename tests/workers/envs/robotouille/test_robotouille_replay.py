"""Every recorded real-engine trajectory replays identically on our engine (via replay_file)."""

from __future__ import annotations

import json

import pytest

from workers.envs.robotouille.data import DataFileError
from workers.envs.robotouille.replay import replay_file

from .helpers import DATA, require_data

EXPECTED = {
    "T1_sync_0_cheese_sandwich_seed42_solved.json": 7,
    "T2_sync_1_lettuce_sandwich_seed42_solved.json": 14,
    "T3_async_0_cheese_chicken_sandwich_seed42_solved.json": 19,
    "T4_async_5_potato_soup_seed42_solved.json": 24,
    "T6_async_0_cheese_chicken_sandwich_seed252_two_cooks_quirk.json": 21,
    # picks the patty up from the stove while it cooks (step 25) and puts it back (step 27)
    "T7_sync_0_cheese_sandwich_seed126_pickup_while_cooking.json": 45,
}
T6 = "T6_async_0_cheese_chicken_sandwich_seed252_two_cooks_quirk.json"
#: every trajectory in the data folder (found at collection time) and every expected one
ALL_FILES = sorted(set(EXPECTED) | {p.name for p in (DATA / "trajectories").glob("T*.json")})


def test_every_trajectory_file_is_covered():
    require_data()
    assert sorted(p.name for p in (DATA / "trajectories").glob("T*.json")) == sorted(EXPECTED)


@pytest.mark.parametrize("name", ALL_FILES)
def test_trajectory_replays_identically(name):
    """Observation text, valid actions in order, done, true predicates and effects, at every step."""
    assert name in EXPECTED, f"{name}: a new trajectory file; add its step count to EXPECTED"
    ok, message = replay_file(str(require_data() / "trajectories" / name))
    assert (ok, message) == (True, f"{EXPECTED[name]} steps identical")


def test_every_trajectory_replays_through_the_environment_api():
    """The same actions through RobotouilleEnv.step: the recorded observation, actions and done."""
    from workers.envs.robotouille.domain import load_domain
    from workers.envs.robotouille.env import RobotouilleEnv

    checked = 0
    for name in ALL_FILES:
        record = json.loads((require_data() / "trajectories" / name).read_text())
        env = RobotouilleEnv(
            domain=load_domain(DATA),
            problem_json=record["generated_environment_json"],
            source=name,
            instance_id=name,
            split="test",
            task=name,
            layout_seed=record["seed"],
            optimal_steps=None,
            max_steps=len(record["steps"]) + 1,
        )
        reset = env.reset()
        assert reset.observation == record["initial"]["observation"], name
        for t, step in enumerate(record["steps"], start=1):
            result = env.step(step["action"])
            assert result.observation == step["observation"], (name, t)
            assert list(result.valid_actions) == step["valid_actions"], (name, t)
            assert result.done == step["done"], (name, t)
            checked += 1
    assert checked == sum(EXPECTED.values())


def test_timer_skip_quirk_second_cook_finishes_one_step_late():
    """T6: cook chicken1 at step 4, chicken2 at step 6; chicken2 is cooked after step 10, not 9."""
    from workers.envs.robotouille.domain import load_domain
    from workers.envs.robotouille.problem import build_problem

    record = json.loads((require_data() / "trajectories" / T6).read_text())
    problem = build_problem(load_domain(DATA), record["generated_environment_json"])
    state = problem.state
    cooked_after = {}
    for t, step in enumerate(record["steps"], start=1):
        state.apply(next(g for g in state.valid_groundings() if g.text == step["action"]))
        for chicken in ("chicken1", "chicken2"):
            if state.is_true("iscooked", chicken):
                cooked_after.setdefault(chicken, t)
    assert cooked_after == {"chicken1": 7, "chicken2": 10}


def test_replay_reports_the_first_difference(tmp_path):
    record = json.loads((require_data() / "trajectories" / sorted(EXPECTED)[0]).read_text())
    record["steps"][2]["observation"] = record["steps"][2]["observation"].replace("cheese1", "cheese9", 1)
    changed = tmp_path / "tampered.json"
    changed.write_text(json.dumps(record))
    ok, message = replay_file(str(changed), data_dir=str(DATA))
    assert not ok
    assert message.startswith("step 3 ('Stack cheese1 on top of bread1 using robot1'): observation differs: line ")
    assert "cheese9" in message


def test_replay_of_an_action_the_engine_rejects(tmp_path):
    record = json.loads((require_data() / "trajectories" / sorted(EXPECTED)[0]).read_text())
    record["steps"][0]["action"] = "Fly robot1 to the moon"
    changed = tmp_path / "bad_action.json"
    changed.write_text(json.dumps(record))
    assert replay_file(str(changed), data_dir=str(DATA)) == (
        False,
        "step 1 ('Fly robot1 to the moon'): action is not valid in our engine",
    )


def test_replay_of_malformed_json_names_the_file(tmp_path):
    broken = tmp_path / "broken.json"
    broken.write_text('{"steps": [')
    with pytest.raises(DataFileError, match="malformed JSON in Robotouille data file .*broken.json"):
        replay_file(str(broken), data_dir=str(DATA))
