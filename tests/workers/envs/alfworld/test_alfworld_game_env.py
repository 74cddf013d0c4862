"""Real ALFWorld games (textworld engine): reset, step, invalid commands, the expert, the cap."""

from __future__ import annotations

import subprocess
import sys

import pytest

from recap.env import EnvError, InvalidActionError
from tests.workers.envs.alfworld.helpers import DATA, DATA_2_1_2, HEAT_ID, HEAT_START, REPO, win_by_expert
from workers.envs.alfworld import AlfworldBenchmark
from workers.envs.alfworld.task_types import TASK_TYPES

HEAT_PLAN_2_1_1 = [
    "go to garbagecan 1",
    "take apple 2 from garbagecan 1",
    "go to microwave 1",
    "heat apple 2 with microwave 1",
    "go to fridge 1",
    "open fridge 1",
    "put apple 2 in/on fridge 1",
]


@pytest.fixture(scope="module")
def bench() -> AlfworldBenchmark:
    return AlfworldBenchmark(DATA)


@pytest.fixture(scope="module")
def heat_env(bench):
    env = bench.make(HEAT_ID)
    yield env
    env.close()


@pytest.mark.parametrize("short", list(TASK_TYPES))
def test_one_game_per_type_wins_by_expert_replay(bench, short):
    env = bench.make(bench.list_instances(short)[0])
    try:
        assert (env.split, env.task, env.benchmark) == (short, TASK_TYPES[short], "alfworld")
        assert env.invalid_action_mode == "step" and env.max_steps == 50
        plan = win_by_expert(env)
        assert all(" in/on " in a for a in plan if a.startswith("put "))
        assert not any(a.startswith("move ") for a in plan)
        assert env.steps_taken == len(plan)
        assert env.demonstration().name == f"alfworld-{short}"
    finally:
        env.close()


def test_reset_gives_text_without_banner_and_the_goal(heat_env):
    reset = heat_env.reset()
    assert reset.observation == HEAT_START
    assert reset.goal == "heat some apple and put it in fridge"
    assert reset.valid_actions[:2] == ("go to cabinet 1", "go to cabinet 2")
    assert reset.valid_actions[-2:] == ("inventory", "look")
    assert len(reset.valid_actions) == 27
    assert heat_env.expert_plan() == HEAT_PLAN_2_1_1


def test_invalid_command_is_sent_answers_nothing_happens_and_changes_nothing(heat_env):
    start = heat_env.reset()
    for i, command in enumerate(["take apple 2 from garbagecan 1", "put the apple somewhere", ""], 1):
        step = heat_env.step(command)
        assert step.observation == "Nothing happens."
        assert step.valid_actions == start.valid_actions
        assert (step.done, step.success) == (False, False)
        assert step.info["steps"] == i == heat_env.steps_taken
    assert heat_env.expert_plan() == HEAT_PLAN_2_1_1  # the expert did not advance
    arrive = heat_env.step("go to garbagecan 1")
    assert arrive.observation == (
        "You arrive at loc 31. On the garbagecan 1, you see a apple 2, a apple 1, a egg 2, a egg 1, a potato 2, and a potato 1."
    )
    assert "take apple 2 from garbagecan 1" in arrive.valid_actions
    assert heat_env.expert_plan() == HEAT_PLAN_2_1_1[1:]
    with pytest.raises(InvalidActionError, match="^an ALFWorld action is a string, got int$"):
        heat_env.step(3)  # type: ignore[arg-type]


def test_reset_starts_over(heat_env):
    heat_env.reset()
    heat_env.step("go to garbagecan 1")
    again = heat_env.reset()
    assert again.observation == HEAT_START
    assert heat_env.steps_taken == 0
    assert heat_env.expert_plan() == HEAT_PLAN_2_1_1


def test_step_cap_ends_the_episode_without_success(bench):
    env = bench.make(HEAT_ID, max_steps=2)
    try:
        with pytest.raises(EnvError, match="call reset\\(\\) before step\\(\\)$"):
            env.step("look")
        env.reset()
        assert env.step("look").done is False
        last = env.step("inventory")
        assert (last.done, last.success, last.info["steps"], last.info["max_steps"]) == (True, False, 2, 2)
        with pytest.raises(EnvError) as err:
            env.step("look")
        assert str(err.value) == f"{HEAT_ID}: the episode is over; call reset() to play again"
        assert "uses one of your 2 steps" in env.rules()
        demo_env = env.demonstration().make_env()
        demo_env.reset()
        assert demo_env.max_steps == 50
        steps = [demo_env.step(r["action"]) for r in env.demonstration().replies["act"]]
        assert steps[-1].success and len(steps) == 8
    finally:
        env.close()
    with pytest.raises(EnvError, match="the environment is closed; make a new one$"):
        env.reset()


def test_version_2_1_2_plays_move_wording(bench):
    env = bench.make(HEAT_ID, version="2.1.2", data_dir_2_1_2=DATA_2_1_2)
    try:
        reset = env.reset()
        assert reset.observation == HEAT_START
        assert "help" in reset.valid_actions
        assert env.game_file == DATA_2_1_2 / "json_2.1.1/valid_unseen" / HEAT_ID.split("/", 2)[2] / "game.tw-pddl"
        assert env.expert_plan()[-1] == "move apple 2 to fridge 1"
        assert env.step("go to garbagecan 1").observation.startswith("You arrive at garbagecan 1. ")
        env.reset()
        plan = win_by_expert(env)
        assert plan[-1] == "move apple 2 to fridge 1"
        assert "move <object> to <receptacle>" in env.rules()
        assert "move potato 1 to diningtable 1" in [r["action"] for r in env.demonstration().replies["act"]]
    finally:
        env.close()


def test_no_expert_without_2_1_2_data(monkeypatch, tmp_path):
    monkeypatch.delenv("ALFWORLD_DATA_2_1_2", raising=False)
    primary = tmp_path / "alf"
    primary.mkdir()
    (primary / "json_2.1.1").symlink_to(DATA / "json_2.1.1")
    env = AlfworldBenchmark(primary).make(HEAT_ID)
    try:
        assert env.expert_plan() is None
        assert env.reset().goal == "heat some apple and put it in fridge"
    finally:
        env.close()


def test_home_folder_is_not_written(tmp_path):
    """With ALFWORLD_DATA unset, the data folder in use is exported before alfworld is imported."""
    code = (
        "import os\n"
        "from workers.envs.alfworld import AlfworldBenchmark\n"
        f"env = AlfworldBenchmark({str(DATA)!r}).make({HEAT_ID!r})\n"
        "print(env.reset().goal, os.environ['ALFWORLD_DATA'] == "
        f"{str(DATA)!r})"
    )
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == "heat some apple and put it in fridge True"
    assert list(tmp_path.iterdir()) == []


def _planner_copies_mapped() -> int:
    with open("/proc/self/maps") as maps:
        return len(
            {
                line.split()[-2] if line.rstrip().endswith("(deleted)") else line.split()[-1]
                for line in maps
                if "libdownward" in line
            }
        )


def test_a_closed_game_hands_its_planner_library_to_the_next(bench):
    """textworld loads a private planner library per game and never unloads it; closing a game
    must let the next game reuse that copy instead of mapping yet another one."""
    first = bench.make(bench.list_instances("puttwo")[0])
    first.reset()
    first.close()
    mapped = _planner_copies_mapped()
    second = bench.make(bench.list_instances("examine")[1])
    try:
        assert win_by_expert(second)
        assert _planner_copies_mapped() == mapped
    finally:
        second.close()
    assert _planner_copies_mapped() == mapped
