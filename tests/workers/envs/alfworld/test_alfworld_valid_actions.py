"""The ``show_valid_actions`` setting: the valid actions after every observation, in the real
games and in the demonstrations' replays, and agents (with the offline expert) still winning."""

from __future__ import annotations

import pytest

from recap.baselines.adapt import ADaPTAgent
from recap.baselines.react import ReActAgent, ReActConfig
from recap.config import ReCAPConfig
from recap.recap_agent import ReCAPAgent
from recap.scripted import ScriptedClient
from tests.workers.envs.alfworld.helpers import DATA, HEAT_ID, HEAT_START, win_by_expert
from workers.envs.alfworld import AlfworldBenchmark
from workers.envs.alfworld.benchmark import SHOW_VALID_ACTIONS, show_valid_actions_for
from workers.envs.alfworld.demos import demonstration_for, demonstration_name
from workers.envs.alfworld.observation import (
    VALID_ACTIONS_HEADER,
    check_show_valid_actions,
    render_observation,
    with_valid_actions,
)
from workers.envs.registry import make_env
from workers.llm.offline.expert import expert_reply
from workers.llm.offline.knobs import Knobs

HEAT_ARRIVE = (
    "You arrive at loc 31. On the garbagecan 1, you see a apple 2, a apple 1, a egg 2, a egg 1, a potato 2, and a potato 1."
)
_GO_TO = (
    "go to cabinet 1\ngo to cabinet 2\ngo to cabinet 3\ngo to cabinet 4\ngo to cabinet 5\n"
    "go to cabinet 6\ngo to coffeemachine 1\ngo to countertop 1\ngo to countertop 2\n"
    "go to countertop 3\ngo to drawer 1\ngo to drawer 2\ngo to drawer 3\ngo to fridge 1\n"
)
_GO_ON = (
    "go to microwave 1\ngo to shelf 1\ngo to shelf 2\ngo to shelf 3\ngo to sinkbasin 1\n"
    "go to stoveburner 1\ngo to stoveburner 2\ngo to stoveburner 3\ngo to stoveburner 4\n"
    "go to toaster 1\ninventory\nlook"
)
#: the valid actions at the start, as the agent reads them
START_LIST = "\n\nValid actions:\n" + _GO_TO + "go to garbagecan 1\n" + _GO_ON
#: the valid actions at garbagecan 1
ARRIVE_LIST = (
    "\n\nValid actions:\nexamine garbagecan 1\n" + _GO_TO + _GO_ON + "\n"
    "take apple 1 from garbagecan 1\ntake apple 2 from garbagecan 1\ntake egg 1 from garbagecan 1\n"
    "take egg 2 from garbagecan 1\ntake potato 1 from garbagecan 1\ntake potato 2 from garbagecan 1"
)


@pytest.fixture(scope="module")
def bench() -> AlfworldBenchmark:
    return AlfworldBenchmark(DATA)


def _play(env):
    """reset, an invalid command, a valid step, an invalid command: the four observations."""
    try:
        reset = env.reset()
        texts = [reset.observation]
        for command in ("take apple 2 from garbagecan 1", "go to garbagecan 1", "open garbagecan 1"):
            texts.append(env.step(command).observation)
        return reset, texts
    finally:
        env.close()


@pytest.mark.parametrize("setting", [None, False])
def test_without_the_setting_observations_are_the_game_text(bench, setting):
    options = {} if setting is None else {"show_valid_actions": setting}
    env = bench.make(HEAT_ID, **options)
    assert env.show_valid_actions is False  # None: not decided by the environment, acts as off
    reset, texts = _play(env)
    assert texts == [HEAT_START, "Nothing happens.", HEAT_ARRIVE, "Nothing happens."]
    assert len(reset.valid_actions) == 27


def test_with_the_setting_every_observation_ends_with_the_valid_actions(bench):
    env = bench.make(HEAT_ID, show_valid_actions=True)
    assert env.show_valid_actions is True and env.partially_observed is True
    reset, texts = _play(env)
    assert texts == [
        HEAT_START + START_LIST,
        "Nothing happens." + START_LIST,
        HEAT_ARRIVE + ARRIVE_LIST,
        "Nothing happens." + ARRIVE_LIST,
    ]
    # the goal and the valid actions themselves do not change
    assert reset.goal == "heat some apple and put it in fridge"
    assert START_LIST == "\n\nValid actions:\n" + "\n".join(reset.valid_actions)


def test_the_registry_passes_the_option_and_the_expert_still_wins():
    env = make_env(HEAT_ID, data_dir=DATA, **{SHOW_VALID_ACTIONS: True})
    try:
        plan = win_by_expert(env)
        assert plan[-1] == "put apple 2 in/on fridge 1"
        env.reset()
        step = env.step(plan[0])
        assert step.observation == HEAT_ARRIVE + "\n\n" + VALID_ACTIONS_HEADER + "\n" + "\n".join(step.valid_actions)
        assert step.info["admissible_commands"] == step.valid_actions
    finally:
        env.close()


def test_the_setting_values_and_the_per_style_choice():
    assert [check_show_valid_actions(v) for v in (None, False, True)] == [False, False, True]
    for bad in ("yes", 1, 0):
        with pytest.raises(ValueError, match="^show_valid_actions must be true, false or null \\(None\\), got "):
            check_show_valid_actions(bad)
    assert SHOW_VALID_ACTIONS == "show_valid_actions"
    assert {s: show_valid_actions_for(s) for s in ("recap", "react", "act", "cot", "standard", "adapt")} == {
        "recap": True,
        "react": False,
        "act": False,
        "cot": False,
        "standard": False,
        "adapt": False,
    }
    assert with_valid_actions("Nothing happens.", ("look", "inventory")) == "Nothing happens.\n\nValid actions:\nlook\ninventory"
    assert with_valid_actions("x", ()) == "x\n\nValid actions:\n(none)"
    assert render_observation("x", ("look",), False) == "x"


# -- the demonstrations ---------------------------------------------------------------------------


def test_replay_observations_follow_the_setting():
    demo = demonstration_for("cool", show_valid_actions=True)
    assert demo.name == "alfworld-cool-valid-actions"
    env = demo.make_env()
    reset = env.reset()
    assert reset.observation == (
        "You are in the middle of a room. Looking quickly around you, you see a cabinet 2, a cabinet 1, "
        "a countertop 2, a countertop 1, a diningtable 1, a drawer 1, a fridge 1, a garbagecan 1, "
        "a microwave 1, a sinkbasin 1, a stoveburner 1, and a toaster 1.\n\n"
        "Your task is to: put a cool tomato in countertop.\n\n"
        "Valid actions:\ngo to cabinet 1\ngo to cabinet 2\ngo to countertop 1\ngo to countertop 2\n"
        "go to diningtable 1\ngo to drawer 1\ngo to fridge 1\ngo to garbagecan 1\ngo to microwave 1\n"
        "go to sinkbasin 1\ngo to stoveburner 1\ngo to toaster 1\ninventory\nlook"
    )
    start_list = reset.observation[reset.observation.index("\n\nValid actions:\n") :]
    assert env.step("take tomato 1 from diningtable 1").observation == "Nothing happens." + start_list
    assert env.step("go to diningtable 1").observation == (
        "You arrive at loc 13. On the diningtable 1, you see a bread 1, a tomato 1, and a winebottle 1.\n\n"
        "Valid actions:\nexamine diningtable 1\ngo to cabinet 1\ngo to cabinet 2\ngo to countertop 1\n"
        "go to countertop 2\ngo to drawer 1\ngo to fridge 1\ngo to garbagecan 1\ngo to microwave 1\n"
        "go to sinkbasin 1\ngo to stoveburner 1\ngo to toaster 1\ninventory\nlook\n"
        "take bread 1 from diningtable 1\ntake tomato 1 from diningtable 1\ntake winebottle 1 from diningtable 1"
    )
    off = demonstration_for("cool").make_env()
    assert off.reset().observation == reset.observation[: reset.observation.index("\n\nValid actions:")]
    assert off.step("take tomato 1 from diningtable 1").observation == "Nothing happens."


def test_demonstration_names_differ_per_variant():
    names = {demonstration_name("put", v, s) for v in ("2.1.1", "2.1.2") for s in (False, True)}
    assert names == {"alfworld-put", "alfworld-put-2.1.2", "alfworld-put-valid-actions", "alfworld-put-2.1.2-valid-actions"}
    assert demonstration_for("put", "2.1.2", show_valid_actions=True).name == "alfworld-put-2.1.2-valid-actions"


@pytest.mark.parametrize("setting", [None, False, True])
def test_the_episode_demonstration_uses_the_episode_setting(bench, setting):
    env = bench.make(HEAT_ID, show_valid_actions=setting)
    try:
        demo = env.demonstration()
        assert demo.name == ("alfworld-heat-valid-actions" if setting else "alfworld-heat")
        demo_env = demo.make_env()
        assert demo_env.show_valid_actions is bool(setting) and demo_env.partially_observed is True
        texts = {
            "react": ReActAgent(ReActConfig()).render_demonstration(demo),
            "recap": ReCAPAgent(ReCAPConfig()).render_demonstration(demo),
        }
    finally:
        env.close()
    fridge = "You arrive at loc 16. The fridge 1 is closed."
    for style, text in texts.items():
        assert fridge in text, style
        if setting:
            # the observation after "go to fridge 1", followed by its valid actions
            assert fridge + "\n\nValid actions:\nclose fridge 1" not in text  # still closed
            assert fridge + "\n\nValid actions:\nexamine fridge 1\ngo to cabinet 1\n" in text, style
            assert text.count("\n\nValid actions:\n") >= 8, style  # start + every step
        else:
            assert VALID_ACTIONS_HEADER not in text, style


# -- agents driven by the offline expert ------------------------------------------------------------


AGENTS = {
    "recap": lambda: ReCAPAgent(ReCAPConfig()),
    "react": lambda: ReActAgent(ReActConfig()),
    "adapt": lambda: ADaPTAgent(),
}


@pytest.mark.parametrize("style", list(AGENTS))
def test_offline_expert_wins_with_the_lists_shown(bench, style):
    """The offline expert reads hints only (never an observation): it still wins, with the
    demonstration pinned, and every observation the model was shown lists the valid actions."""
    env = bench.make(HEAT_ID, show_valid_actions=True)

    def expert(request):
        return expert_reply({**request.hints, "expert_plan": env.expert_plan()}, Knobs(), f"ep#{request.call_index}")

    client = ScriptedClient([expert] * 200)
    try:
        result = AGENTS[style]().run(env, client, episode_id="ep", emit=lambda r: None, demonstration=True)
    finally:
        env.close()
    assert (result.success, result.end_reason, result.steps) == (True, "success", 7)
    shown = {m.content for r in client.requests for m in r.messages if m.role == "user"}
    assert any(HEAT_ARRIVE + ARRIVE_LIST in text for text in shown)  # the first step's answer


def _work(instance_id, **env_options):
    from schemas.outcomes import UnitWork

    return UnitWork(
        unit_id="u",
        instance_id=instance_id,
        method="react",
        method_config="{}",
        model_label="m",
        model="offline/expert",
        sampling_seed=1,
        step_multiplier=1.0,
        env_options=tuple(sorted(env_options.items())),
    )


def test_the_worker_fills_the_setting_per_method_and_a_sweep_option_wins():
    """The pipeline asks the benchmark what each method runs with: ReCAP sees the valid actions
    on ALFWorld, ReAct does not; a sweep's explicit option overrides either."""
    from recap.methods import make_agent
    from workers.episode_worker import env_options_for

    unit = _work("alfworld/heat/x", data_dir="d")
    assert env_options_for(unit, make_agent("recap")) == {"show_valid_actions": True, "data_dir": "d"}
    assert env_options_for(unit, make_agent("react")) == {"show_valid_actions": False, "data_dir": "d"}
    assert env_options_for(unit, make_agent("adapt")) == {"show_valid_actions": False, "data_dir": "d"}
    forced = _work("alfworld/heat/x", show_valid_actions=True)
    assert env_options_for(forced, make_agent("react")) == {"show_valid_actions": True}
    # other benchmarks choose nothing per method
    assert env_options_for(_work("blocksworld/3@1"), make_agent("recap")) == {}
