"""The expert planner solves every instance, within 1.5 x optimal, from any reachable state."""

from __future__ import annotations

import random

import pytest

from workers.envs.robotouille import BENCHMARK
from workers.envs.robotouille.planner import Planner, expert_plan

from .helpers import DATA, all_refs, one_seed_per_task, require_data

#: actions that can make a goal unreachable (an item poured or added where it cannot come back)
IRREVERSIBLE = ("Add ", "Fill bowl")


def _run(env, plan):
    step = None
    for action in plan:
        step = env.step(action)
    return step


def test_expert_solves_all_200_within_one_and_a_half_times_optimal():
    require_data()
    too_long, unsolved = [], []
    worst = 0.0
    for ref in all_refs():
        env = BENCHMARK.make(ref.instance_id, data_dir=str(DATA), step_multiplier=1.5)
        env.reset()
        plan = env.expert_plan()
        if plan is None:
            unsolved.append(ref.instance_id)
            continue
        if len(plan) > env.optimal_steps * 1.5:
            too_long.append((ref.instance_id, len(plan), env.optimal_steps))
        last = _run(env, plan)
        if not (last.done and last.success):
            unsolved.append(ref.instance_id)
        worst = max(worst, len(plan) / env.optimal_steps)
    assert unsolved == [] and too_long == []
    assert worst <= 1.5


@pytest.mark.parametrize("ref", one_seed_per_task(3), ids=lambda r: f"{r.split[:5]}-{r.task.split('_')[0]}")
def test_expert_replans_from_messy_states(ref):
    """Half the plan, then random reversible detours, then a fresh plan: it still succeeds."""
    rng = random.Random(ref.instance_id)
    for trial in range(4):
        env = BENCHMARK.make(ref.instance_id, data_dir=str(DATA), step_multiplier=50)
        env.reset()
        plan = env.expert_plan()
        _run(env, plan[: len(plan) // 2])
        for _ in range(rng.randint(3, 25)):
            options = [a for a in env.valid_actions() if not a.startswith(IRREVERSIBLE)]
            step = env.step(rng.choice(options))
            if step.done:
                break
        if env.done:
            continue
        replan = env.expert_plan()
        assert replan is not None, (ref.instance_id, trial)
        last = _run(env, replan)
        assert last.done and last.success, (ref.instance_id, trial)


def test_expert_plan_is_empty_once_solved_and_none_when_unreachable():
    env = BENCHMARK.make("robotouille/asynchronous/5_potato_soup@42", data_dir=str(DATA))
    env.reset()
    plan = env.expert_plan()
    _run(env, plan)
    assert env.expert_plan() == []

    # pour the water into the bowl before it boils: the soup can never be finished
    env = BENCHMARK.make("robotouille/asynchronous/5_potato_soup@42", data_dir=str(DATA))
    env.reset()
    prefix = plan[: plan.index("Fill pot1 with water from sink2 using robot1") + 1]
    _run(env, prefix)
    for _ in range(3):
        env.step("Do nothing")
    _run(
        env,
        [
            "Pick up pot1 from sink2 using robot1",
            "Move robot1 from sink2 to board2",
            "Fill bowl1 with pot1's contents using robot1",
        ],
    )
    assert "water1 is inside of bowl1" in env.observation()
    planner = Planner(env.state, env.problem.goal)
    assert planner.plan(env.state, 400) is None
    assert planner.failure == "unreachable: some goal role has no usable object"
    assert env.expert_plan() is None


def test_expert_plan_does_not_touch_the_environment():
    env = BENCHMARK.make("robotouille/asynchronous/0_cheese_chicken_sandwich@252", data_dir=str(DATA))
    reset = env.reset()
    plan = expert_plan(env.state, env.problem.goal)
    assert plan and env.observation() == reset.observation and env.steps_taken == 0
