"""The Environment contract: ids and selectors, step caps, stepping, bad input."""

from __future__ import annotations

import json

import pytest

from recap.env import EnvError, InvalidActionError
from workers.envs.registry import DataNotFoundError, UnknownInstanceError, get_benchmark, make_env
from workers.envs.robotouille import BENCHMARK, catalog
from workers.envs.robotouille.data import DataFileError
from workers.envs.robotouille.rules import failure_hints, rules_text

from .helpers import DATA, require_data

POTATO = "robotouille/asynchronous/5_potato_soup@42"


def test_registry_finds_the_benchmark():
    assert get_benchmark("robotouille") is BENCHMARK
    env = make_env(POTATO, data_dir=str(require_data()))
    assert (env.instance_id, env.benchmark, env.split, env.task, env.layout_seed) == (
        POTATO,
        "robotouille",
        "asynchronous",
        "5_potato_soup",
        42,
    )


def test_list_instances_order_and_selectors():
    ids = BENCHMARK.list_instances()
    assert len(ids) == 200 and len(set(ids)) == 200
    assert ids[0] == "robotouille/synchronous/0_cheese_sandwich@42"
    assert ids[9] == "robotouille/synchronous/0_cheese_sandwich@420"
    assert ids[10] == "robotouille/synchronous/1_lettuce_sandwich@42"
    assert ids[100] == "robotouille/asynchronous/0_cheese_chicken_sandwich@42"
    assert ids[-1].startswith("robotouille/asynchronous/9_onion_potato_soup")
    assert ids == BENCHMARK.list_instances(None) == BENCHMARK.list_instances("robotouille")
    assert ids == BENCHMARK.list_instances("all")
    assert BENCHMARK.list_instances("synchronous") == ids[:100]
    assert BENCHMARK.list_instances("asynchronous") == ids[100:]
    potato = [f"robotouille/asynchronous/5_potato_soup@{s}" for s in catalog.LAYOUT_SEEDS]
    assert BENCHMARK.list_instances("asynchronous/5") == potato
    assert BENCHMARK.list_instances("asynchronous/5_potato_soup") == potato
    assert BENCHMARK.list_instances("robotouille/asynchronous/5_potato_soup") == potato
    assert BENCHMARK.list_instances(POTATO) == [POTATO]
    assert all("3.1_lettuce_cheeseburger" not in i for i in ids)


@pytest.mark.parametrize(
    "selector, fragment",
    [
        ("asynchronous/3.1_lettuce_cheeseburger", "tasks: 0_cheese_chicken_sandwich"),
        ("asynchronous/11", "unknown Robotouille task asynchronous/'11'"),
        ("breakfast", "splits are synchronous, asynchronous"),
        ("robotouille/synchronous/0_cheese_sandwich@43", "layout seeds: 42, 84, 126"),
        ("robotouille/synchronous/no_such_task@42", "tasks: 0_cheese_sandwich, 1_lettuce_sandwich"),
    ],
)
def test_unknown_selectors_say_what_exists(selector, fragment):
    with pytest.raises(UnknownInstanceError) as info:
        BENCHMARK.list_instances(selector)
    assert fragment in str(info.value)


def test_unknown_instance_id_in_make():
    with pytest.raises(UnknownInstanceError, match="unknown layout seed 7 .* layout seeds: 42, 84"):
        BENCHMARK.make("robotouille/asynchronous/5_potato_soup@7", data_dir=str(DATA))
    with pytest.raises(UnknownInstanceError, match="ids look like robotouille/<synchronous|asynchronous>"):
        BENCHMARK.make("robotouille/potato_soup", data_dir=str(DATA))


@pytest.mark.parametrize("multiplier, expected", [(4.0, 76), (1.5, 29), (3, 57)])
def test_max_steps_is_ceil_of_optimal_times_multiplier(multiplier, expected):
    env = BENCHMARK.make(POTATO, data_dir=str(DATA), step_multiplier=multiplier)
    assert env.optimal_steps == 19
    assert env.max_steps == expected


def test_default_multiplier_is_the_papers_four():
    env = BENCHMARK.make("robotouille/synchronous/6_lettuce_tomato_cheeseburger@42", data_dir=str(DATA))
    assert (env.optimal_steps, env.max_steps) == (36, 144)


def test_step_counts_and_info():
    env = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA))
    env.reset()
    step = env.step("Pick up cheese1 from table1 using robot1")
    assert step.info == {"steps": 1, "max_steps": 40, "success": False, "truncated": False}
    assert not step.done and not step.success
    assert step.valid_actions[-1] == "Do nothing"
    assert "robot1 is holding cheese1" in step.observation
    assert env.steps_taken == 1


def test_episode_ends_unsuccessfully_at_max_steps():
    env = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA), step_multiplier=0.2)
    assert env.max_steps == 2
    env.reset()
    first = env.step("Do nothing")
    assert not first.done
    last = env.step("Do nothing")
    assert (last.done, last.success, last.info["truncated"], last.info["steps"]) == (True, False, True, 2)
    with pytest.raises(EnvError, match="episode is over"):
        env.step("Do nothing")


def test_invalid_action_is_rejected_and_changes_nothing():
    env = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA))
    reset = env.reset()
    for bad in [
        "Pick up cheese1 from table1",
        "pick up cheese1 from table1 using robot1",
        "Move robot1 from table1 to table1",
        "",
    ]:
        with pytest.raises(InvalidActionError) as info:
            env.step(bad)
        assert repr(bad) in str(info.value)
    assert env.steps_taken == 0
    assert env.observation() == reset.observation
    assert env.valid_actions() == reset.valid_actions
    # and the episode continues normally afterwards
    assert env.step("Pick up cheese1 from table1 using robot1").info["steps"] == 1


def test_failure_hints_name_the_usual_causes_and_the_closest_action():
    env = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA))
    env.reset()
    with pytest.raises(InvalidActionError):
        env.step("Pick up cheese1 from table1 with robot1")
    hints = env.failure_hints()
    assert hints.startswith(failure_hints())
    assert hints.endswith("The closest valid action is: Pick up cheese1 from table1 using robot1")
    for topic in ("exactly", "occupied", "cut, cooked or fried", "underneath"):
        assert topic in hints


def test_rules_differ_for_sync_and_async():
    sync, async_ = rules_text("synchronous"), rules_text("asynchronous")
    for text in (sync, async_):
        for topic in (
            "Station",
            "Item",
            "Player",
            "Container",
            "Meal",
            "at most one item",
            "three times",
            "stacks it on top",
            "Sandwich",
            "Hamburger",
            "Soup",
        ):
            assert topic in text
    assert "Do nothing action once for each" in async_ and "Do nothing" not in sync
    env = BENCHMARK.make(POTATO, data_dir=str(DATA))
    assert env.rules() == async_


def test_reset_starts_a_fresh_episode():
    env = BENCHMARK.make("robotouille/synchronous/0_cheese_sandwich@42", data_dir=str(DATA))
    first = env.reset()
    env.step("Pick up cheese1 from table1 using robot1")
    again = env.reset()
    assert again == first and env.steps_taken == 0


def test_step_before_reset_is_an_error():
    env = BENCHMARK.make(POTATO, data_dir=str(DATA))
    with pytest.raises(EnvError, match="step\\(\\) before reset\\(\\)"):
        env.step("Do nothing")


def test_data_folder_from_environment_variable(monkeypatch, tmp_path):
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(require_data()))
    assert BENCHMARK.make(POTATO).reset().goal.startswith("Make potato soup")
    monkeypatch.delenv("ROBOTOUILLE_DATA")
    # nothing in the caches or next to the checkout either (workers/envs/data_paths.py)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("RECAP_EVAL_CACHE", raising=False)
    monkeypatch.setattr("workers.envs.data_paths.CHECKOUT_DATA_ROOT", tmp_path / "none")
    with pytest.raises(DataNotFoundError, match="pass data_dir=... or set ROBOTOUILLE_DATA"):
        BENCHMARK.make(POTATO)


def test_missing_or_wrong_data_folder(tmp_path):
    with pytest.raises(DataNotFoundError, match="does not exist"):
        BENCHMARK.make(POTATO, data_dir=str(tmp_path / "nowhere"))
    with pytest.raises(DataNotFoundError, match="is not a Robotouille data folder: domain/robotouille.json is missing"):
        BENCHMARK.make(POTATO, data_dir=str(tmp_path))


def _fake_data_dir(tmp_path, instance_text: str):
    (tmp_path / "domain").mkdir()
    (tmp_path / "domain" / "robotouille.json").symlink_to(DATA / "domain" / "robotouille.json")
    folder = tmp_path / "instances" / "asynchronous"
    folder.mkdir(parents=True)
    (folder / "5_potato_soup_42.json").write_text(instance_text)
    return tmp_path


def test_malformed_instance_json_names_the_file(tmp_path):
    root = _fake_data_dir(tmp_path, '{"generated_environment_json": {"stations": [}')
    with pytest.raises(DataFileError, match=r"malformed JSON in Robotouille data file .*5_potato_soup_42\.json.*line 1"):
        BENCHMARK.make(POTATO, data_dir=str(root))


def test_instance_without_problem_names_the_field(tmp_path):
    root = _fake_data_dir(tmp_path, json.dumps({"seed": 42}))
    with pytest.raises(DataFileError, match="5_potato_soup_42.json' has no field 'generated_environment_json'"):
        BENCHMARK.make(POTATO, data_dir=str(root))


def test_missing_instance_file(tmp_path):
    root = _fake_data_dir(tmp_path, "{}")
    with pytest.raises(DataNotFoundError, match="5_potato_soup_84.json' does not exist"):
        BENCHMARK.make("robotouille/asynchronous/5_potato_soup@84", data_dir=str(root))


def test_unknown_options_and_engines():
    with pytest.raises(TypeError, match="unknown Robotouille option"):
        BENCHMARK.make(POTATO, data_dir=str(DATA), colour="red")
    with pytest.raises(ValueError, match="unknown Robotouille engine 'fast'"):
        BENCHMARK.make(POTATO, data_dir=str(DATA), engine="fast")
    with pytest.raises(ValueError, match="step_multiplier must be positive"):
        BENCHMARK.make(POTATO, data_dir=str(DATA), step_multiplier=0)


def test_real_engine_without_the_package_says_so():
    try:
        import robotouille  # noqa: F401
    except ImportError:
        with pytest.raises(EnvError) as info:
            BENCHMARK.make(POTATO, engine="real")
        assert str(info.value) == "the real robotouille package is not installed; engine: ours is the default"
    else:  # pragma: no cover - only where the real package exists
        assert BENCHMARK.make(POTATO, engine="real").reset().observation
