"""The built-in blocksworld environment: ids, exact lookup, invalid actions, the expert."""

from __future__ import annotations

import random

import pytest

from recap.blocksworld import BENCHMARK, BlocksworldEnv
from recap.env import InvalidActionError, UnknownInstanceError


def test_instances_and_errors():
    assert BENCHMARK.list_instances("4") == ["blocksworld/4@1", "blocksworld/4@2", "blocksworld/4@3"]
    with pytest.raises(UnknownInstanceError, match="no blocksworld instance matches '9'"):
        BENCHMARK.list_instances("9")
    with pytest.raises(UnknownInstanceError, match="unknown blocksworld instance 'blocksworld/x'"):
        BENCHMARK.make("blocksworld/x")


def test_invalid_action_changes_nothing():
    env = BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="t", demo=False)
    r = env.reset()
    with pytest.raises(InvalidActionError, match="'pick up C' is not a valid action"):
        env.step("pick up C")
    with pytest.raises(InvalidActionError):
        env.step("pick up")  # a prefix of a valid action is not a match
    assert env.expert_plan()[0] == "unstack C from A" and env.steps_taken == 0
    s = env.step("unstack C from A")
    assert s.valid_actions == ("put down C", "stack C on A", "stack C on B") and r.valid_actions == (
        "pick up B",
        "unstack C from A",
    )


@pytest.mark.parametrize("iid", BENCHMARK.list_instances())
def test_closed_loop_expert_solves_from_random_states(iid):
    for seed in range(10):
        rng = random.Random(seed)
        env = BENCHMARK.make(iid, step_multiplier=100)
        valid = env.reset().valid_actions
        step = None
        for _ in range(rng.randint(0, 6)):
            step = env.step(rng.choice(valid))
            valid = step.valid_actions
            if step.success:
                break
        if step is not None and step.success:
            assert env.expert_plan() == []
            continue
        for _n in range(60):
            plan = env.expert_plan()
            step = env.step(plan[0])
            if step.success:
                break
        assert step.success, (iid, seed)
