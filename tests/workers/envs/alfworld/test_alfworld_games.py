"""Game discovery, ids, selectors and data-folder errors (no textworld needed)."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest

from tests.workers.envs.alfworld.helpers import DATA, DATA_2_1_2, EXPECTED_COUNTS, REPO
from workers.envs.alfworld import BENCHMARK, AlfworldBenchmark
from workers.envs.alfworld.games import discover_games, load_walkthrough, resolve_data_dir_2_1_2
from workers.envs.registry import DataNotFoundError, UnknownInstanceError, get_benchmark, make_env

FIRST_ID = "alfworld/examine/look_at_obj_in_light-AlarmClock-None-DeskLamp-308/trial_T20190908_222917_366542"
HEAT_ID = "alfworld/heat/pick_heat_then_place_in_recep-Apple-None-Fridge-10/trial_T20190906_182259_116320"


@pytest.fixture(scope="module")
def bench() -> AlfworldBenchmark:
    return AlfworldBenchmark(DATA)


def test_registry_finds_the_benchmark():
    assert get_benchmark("alfworld") is BENCHMARK
    assert BENCHMARK.name == "alfworld"


def test_134_games_in_the_order_of_the_shipped_list(bench):
    games = bench.games()
    listed = (DATA / "GAMES_134.txt").read_text().split()
    assert [f"{g.relpath.as_posix()}/game.tw-pddl" for g in games] == listed
    assert len(games) == 134
    assert Counter(g.short_type for g in games) == EXPECTED_COUNTS


def test_ids_are_short_type_game_folder_trial(bench):
    ids = bench.list_instances()
    assert ids[0] == FIRST_ID
    assert len(set(ids)) == 134
    for instance_id in ids:
        bench_name, short, game_dir, trial = instance_id.split("/")
        assert bench_name == "alfworld" and trial.startswith("trial_T")
        assert game_dir.startswith(
            {
                "put": "pick_and_place_simple-",
                "clean": "pick_clean_then_place_in_recep-",
                "heat": "pick_heat_then_place_in_recep-",
                "cool": "pick_cool_then_place_in_recep-",
                "examine": "look_at_obj_in_light-",
                "puttwo": "pick_two_obj_and_place-",
            }[short]
        )


def test_selectors(bench):
    everything = bench.list_instances()
    assert bench.list_instances(None) == everything
    assert bench.list_instances("all") == everything
    assert bench.list_instances("eval_out_of_distribution") == everything
    heat = bench.list_instances("heat")
    assert len(heat) == 23 and all(i.startswith("alfworld/heat/") for i in heat)
    assert bench.list_instances("pick_heat_then_place_in_recep") == heat
    assert bench.list_instances("alfworld/heat") == heat
    assert heat == [i for i in everything if i.startswith("alfworld/heat/")]
    assert bench.list_instances(HEAT_ID) == [HEAT_ID]
    for short, count in EXPECTED_COUNTS.items():
        assert len(bench.list_instances(short)) == count


def test_unknown_selector_lists_what_exists(bench):
    with pytest.raises(UnknownInstanceError) as err:
        bench.list_instances("boil")
    assert str(err.value) == (
        "unknown ALFWorld game or selector 'boil'; use all, a task type "
        f"(put, clean, heat, cool, examine, puttwo), or a full id such as {FIRST_ID}"
    )
    with pytest.raises(UnknownInstanceError, match="unknown ALFWorld game or selector"):
        bench.list_instances(HEAT_ID + "x")


def test_make_needs_one_full_id(bench):
    with pytest.raises(UnknownInstanceError) as err:
        bench.make("alfworld/heat")
    assert str(err.value) == (f"'alfworld/heat' names 23 ALFWorld games; make() needs one full id such as {HEAT_ID}")
    with pytest.raises(UnknownInstanceError, match="unknown ALFWorld game or selector 'alfworld/heat/nope'"):
        make_env("alfworld/heat/nope")


def test_bad_options(bench):
    with pytest.raises(ValueError) as err:
        bench.make(HEAT_ID, version="2.2")
    assert str(err.value) == "unknown ALFWorld game-file version '2.2'; use one of: 2.1.1, 2.1.2"
    with pytest.raises(ValueError) as err:
        bench.make(HEAT_ID, max_step=3)
    assert str(err.value) == (
        "unknown ALFWorld option(s) max_step; accepted: data_dir, data_dir_2_1_2, version, "
        "max_steps, step_multiplier, seed, show_valid_actions, demo_valid_actions"
    )
    with pytest.raises(ValueError, match="^max_steps must be a positive integer, got 0$"):
        bench.make(HEAT_ID, max_steps=0)
    with pytest.raises(ValueError) as err:
        bench.make(HEAT_ID, show_valid_actions="yes")
    assert str(err.value) == "show_valid_actions must be true, false or null (None), got 'yes'"


def test_missing_data_folder(monkeypatch, tmp_path):
    monkeypatch.delenv("ALFWORLD_DATA", raising=False)
    # nothing in the caches or next to the checkout either (workers/envs/data_paths.py)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.delenv("RECAP_EVAL_CACHE", raising=False)
    monkeypatch.setattr("workers.envs.data_paths.CHECKOUT_DATA_ROOT", tmp_path / "none")
    with pytest.raises(DataNotFoundError) as err:
        AlfworldBenchmark().list_instances()
    assert str(err.value).startswith(
        "ALFWorld data folder not set: set ALFWORLD_DATA (or pass data_dir=) to the folder "
        "that holds json_2.1.1/valid_unseen, or run `recap data fetch alfworld` (looked in "
    )
    monkeypatch.setenv("ALFWORLD_DATA", str(tmp_path))
    with pytest.raises(DataNotFoundError) as err:
        AlfworldBenchmark().list_instances()
    assert str(err.value) == (
        f"ALFWorld data folder {tmp_path} (from ALFWORLD_DATA) has no json_2.1.1/valid_unseen; "
        "point ALFWORLD_DATA at the folder that holds it"
    )
    with pytest.raises(DataNotFoundError, match=r"\(from data_dir\) has no json_2.1.1/valid_unseen"):
        AlfworldBenchmark(tmp_path / "nowhere").list_instances()


def test_env_var_is_the_default_data_folder(monkeypatch):
    monkeypatch.setenv("ALFWORLD_DATA", str(DATA))
    assert AlfworldBenchmark().list_instances("cool") == AlfworldBenchmark(DATA).list_instances("cool")


def _fake_trial(root: Path, game_dir: str, trial: str, *, task_type: str, solvable: bool = True, traj: bool = True) -> None:
    folder = root / "json_2.1.1" / "valid_unseen" / game_dir / trial
    folder.mkdir(parents=True)
    if traj:
        (folder / "traj_data.json").write_text(json.dumps({"task_type": task_type}))
    (folder / "game.tw-pddl").write_text(json.dumps({"solvable": solvable}))


def test_selection_rule(tmp_path):
    heat = "pick_heat_then_place_in_recep"
    _fake_trial(tmp_path, f"{heat}-Egg-None-Fridge-1", "trial_T1", task_type=heat)
    _fake_trial(tmp_path, f"{heat}-Egg-None-Fridge-1", "trial_T2", task_type=heat, solvable=False)
    _fake_trial(tmp_path, f"{heat}-Egg-None-Fridge-1", "trial_T3", task_type=heat, traj=False)
    _fake_trial(tmp_path, f"{heat}-EggSliced-None-Fridge-1", "trial_T4", task_type=heat)
    _fake_trial(tmp_path, f"{heat}-Egg-movable-Fridge-1", "trial_T5", task_type=heat)
    _fake_trial(
        tmp_path, "pick_and_place_with_movable_recep-Egg-Pan-Fridge-1", "trial_T6", task_type="pick_and_place_with_movable_recep"
    )
    _fake_trial(tmp_path, "pick_and_place_simple-Egg-None-Fridge-1", "trial_T7", task_type="pick_and_place_simple")
    games = discover_games(tmp_path.resolve())
    assert [g.instance_id for g in games] == [
        "alfworld/put/pick_and_place_simple-Egg-None-Fridge-1/trial_T7",
        f"alfworld/heat/{heat}-Egg-None-Fridge-1/trial_T1",
    ]


def test_no_games_is_an_error(tmp_path):
    (tmp_path / "json_2.1.1" / "valid_unseen").mkdir(parents=True)
    with pytest.raises(DataNotFoundError) as err:
        AlfworldBenchmark(tmp_path).list_instances()
    assert str(err.value) == (
        f"no playable ALFWorld games under {tmp_path.resolve()}/json_2.1.1/valid_unseen; "
        "point ALFWORLD_DATA (or data_dir=) at a complete copy of the data"
    )


def test_2_1_2_folder_resolution(monkeypatch, tmp_path):
    monkeypatch.delenv("ALFWORLD_DATA_2_1_2", raising=False)
    assert resolve_data_dir_2_1_2(DATA) == DATA_2_1_2  # sibling detection
    assert resolve_data_dir_2_1_2(tmp_path) is None
    monkeypatch.setenv("ALFWORLD_DATA_2_1_2", str(DATA_2_1_2))
    assert resolve_data_dir_2_1_2(tmp_path) == DATA_2_1_2
    monkeypatch.setenv("ALFWORLD_DATA_2_1_2", str(tmp_path))
    with pytest.raises(DataNotFoundError) as err:
        resolve_data_dir_2_1_2(DATA)
    assert str(err.value) == (
        f"ALFWorld 2.1.2 data folder {tmp_path} (from ALFWORLD_DATA_2_1_2) has no "
        "json_2.1.1/valid_unseen; point ALFWORLD_DATA_2_1_2 at the alfworld-2.1.2 folder"
    )


def test_version_2_1_2_without_its_data(monkeypatch, tmp_path):
    monkeypatch.delenv("ALFWORLD_DATA_2_1_2", raising=False)
    primary = tmp_path / "alf"
    primary.mkdir()
    (primary / "json_2.1.1").symlink_to(DATA / "json_2.1.1")
    with pytest.raises(DataNotFoundError) as err:
        AlfworldBenchmark(primary).make(HEAT_ID, version="2.1.2")
    assert str(err.value) == (
        "ALFWorld 2.1.2 data not found: set ALFWORLD_DATA_2_1_2 (or pass data_dir_2_1_2=) to the "
        f"alfworld-2.1.2 folder, or place it next to {primary}"
    )


def test_walkthrough_from_the_2_1_2_file(bench):
    game = bench.games(HEAT_ID)[0]
    assert load_walkthrough(DATA_2_1_2, game) == (
        "go to garbagecan 1",
        "take apple 2 from garbagecan 1",
        "go to microwave 1",
        "heat apple 2 with microwave 1",
        "go to fridge 1",
        "open fridge 1",
        "move apple 2 to fridge 1",
    )


def _run_isolated(code: str) -> str:
    proc = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        capture_output=True,
        text=True,
        env={"PATH": "/usr/bin:/bin", "ALFWORLD_DATA": str(DATA)},
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.strip()


def test_package_does_not_import_the_engine_until_a_game_is_made():
    out = _run_isolated(
        "import sys, workers.envs.alfworld as a\n"
        "from workers.envs.alfworld.demos import demonstration_for\n"
        "n = len(a.BENCHMARK.list_instances())\n"
        "demo = demonstration_for('heat')\n"
        "step = demo.make_env().reset()\n"
        "print(n, 'textworld' in sys.modules, 'alfworld' in sys.modules)"
    )
    assert out == "134 False False"


def test_missing_engine_says_how_to_install():
    out = _run_isolated(
        "import sys\n"
        "sys.modules['textworld'] = None\n"
        "from recap.env import EnvError\n"
        "from workers.envs.alfworld import BENCHMARK\n"
        f"try:\n    BENCHMARK.make({HEAT_ID!r})\n"
        "except EnvError as e:\n    print(e)"
    )
    assert out == (
        "ALFWorld games need the optional package 'textworld', which is not installed: "
        "pip install 'recap-eval[alfworld]' (alfworld==0.4.2, textworld 1.7.0)"
    )
