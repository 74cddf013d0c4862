"""Our engine reproduces the real engine's first observation of every benchmark instance."""

from __future__ import annotations

import json

import pytest

from workers.envs.robotouille import BENCHMARK
from workers.envs.robotouille.domain import load_domain
from workers.envs.robotouille.problem import build_problem

from .helpers import DATA, all_refs, instance_record, require_data


def test_all_200_first_observations_match_byte_for_byte():
    require_data()
    mismatches = []
    for ref in all_refs():
        env = BENCHMARK.make(ref.instance_id, data_dir=str(DATA))
        reset = env.reset()
        record = instance_record(ref.split, ref.task, ref.layout_seed)
        if reset.observation != record["initial_observation"]:
            mismatches.append(ref.instance_id)
        # the valid actions of the Reset are the ones listed in the observation, in order
        listed = reset.observation.split("Valid Actions:\n", 1)[1].split("\n\nGoal:", 1)[0].split("\n")
        assert list(reset.valid_actions) == listed
        assert reset.goal == record["generated_environment_json"]["goal_description"]
        assert reset.valid_actions[-1] == "Do nothing"
    assert mismatches == []
    assert len(all_refs()) == 200


@pytest.mark.parametrize("split", ["synchronous_train", "asynchronous_train"])
def test_training_kitchens_first_observation(split):
    domain = load_domain(require_data())
    (path,) = sorted((DATA / "instances_train" / split).glob("*.json"))
    record = json.loads(path.read_text())
    problem = build_problem(domain, record["generated_environment_json"], str(path))
    assert problem.state.observation(problem.goal_description) == record["initial_observation"]


def test_goal_set_counts_match_the_real_engine():
    """Injective assignments of goal ids = the real engine's number of expanded goal sets."""
    domain = load_domain(require_data())
    counts = {}
    for ref in all_refs():
        record = instance_record(ref.split, ref.task, ref.layout_seed)
        problem = build_problem(domain, record["generated_environment_json"])
        assert problem.goal.count_assignments() == record["num_goal_sets"], ref.instance_id
        counts[ref.instance_id] = record["num_goal_sets"]
    # the big ones the real engine needed minutes for
    assert max(counts.values()) == 253440


def test_goal_id_shared_by_two_names_means_the_first_name():
    """sync task 1: the goal's "cheese" slot carries the lettuce's id, so it means the lettuce."""
    domain = load_domain(require_data())
    record = instance_record("synchronous", "1_lettuce_sandwich", 42)
    goal = build_problem(domain, record["generated_environment_json"]).goal
    assert goal.var_names[3] == "lettuce"
    assert goal.domains[3] == ("lettuce1",)


def test_not_yet_created_objects_are_named_as_they_will_be():
    domain = load_domain(require_data())
    record = instance_record("asynchronous", "5_potato_soup", 42)
    goal = build_problem(domain, record["generated_environment_json"]).goal
    water = next(v for v, n in goal.var_names.items() if n == "water")
    assert goal.domains[water] == ("water1",)
