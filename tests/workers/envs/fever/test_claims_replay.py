"""The paper's 200 claims in the release's order, instance ids, the data folder, and trajectory replay."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from pipeline.errors import SpecError
from pipeline.spec import parse_spec
from pipeline.units import resolve_instances
from tests.conftest import SHARED_DATA
from tests.workers.envs.fever.test_observations import ARTICLE_OBS, SIMILAR
from workers.envs.fever import BENCHMARK
from workers.envs.fever.claims import ENV_VAR, ClaimsFileError, paper_indices
from workers.envs.fever.data_folders import CLAIMS_SHA256, FOLDER
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.replay import TrajectoryError, read_trajectory, replay_trajectory
from workers.envs.registry import UnknownInstanceError, get_benchmark

REAL = SHARED_DATA / "fever"


def test_the_release_shuffles_indices_0_to_7404_with_seed_42():
    idxs = paper_indices()
    assert len(idxs) == 200 and len(set(idxs)) == 200 and max(idxs) < 7405
    assert idxs[:5] == [1547, 2054, 478, 3245, 1119]


@pytest.mark.skipif(not (REAL / "paper_dev.jsonl").is_file(), reason="../shared/data/fever/paper_dev.jsonl is absent")
def test_the_paper_set_is_200_claim_ids_in_the_release_order(monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(REAL))
    assert hashlib.sha256((REAL / "paper_dev.jsonl").read_bytes()).hexdigest() == CLAIMS_SHA256
    ids = get_benchmark("fever").list_instances()
    assert ids[:5] == ["fever/168966", "fever/226862", "fever/217220", "fever/128575", "fever/74795"]
    assert ids[-5:] == ["fever/132420", "fever/155174", "fever/94619", "fever/112427", "fever/82886"]
    assert len(ids) == len(set(ids)) == 200
    assert BENCHMARK.list_instances("paper") == ids
    every = BENCHMARK.list_instances("all")
    assert len(every) == 9999 and every[0] == "fever/91198"
    env = BENCHMARK.make("fever/168966", data_dir=str(REAL), limiter=TokenBucket(1000.0, 1000))
    assert env.reset().observation == "Claim: Middle-earth is part of a town in New York."


def test_selectors_and_ids_are_checked(claims_dir):
    bench = type(BENCHMARK)(claims_dir)
    assert bench.list_instances("all") == ["fever/1001", "fever/1002", "fever/1003"]
    with pytest.raises(ClaimsFileError, match="the claims file has 3 claims; the paper's set needs 7405"):
        bench.list_instances()
    with pytest.raises(UnknownInstanceError, match="unknown FEVER selector 'dev'; selectors: paper"):
        bench.list_instances("dev")
    with pytest.raises(UnknownInstanceError, match="no FEVER claim with id 999 in paper_dev.jsonl"):
        bench.make("fever/999")
    with pytest.raises(UnknownInstanceError, match="fever/<claim id>, got 'fever/abc'"):
        bench.make("fever/abc")


def test_a_named_folder_without_claims_is_an_error(tmp_path, monkeypatch):
    monkeypatch.setenv(ENV_VAR, str(tmp_path))
    with pytest.raises(FileNotFoundError, match="is not a FEVER data folder: paper_dev.jsonl is missing"):
        BENCHMARK.list_instances("all")


def test_the_data_folder_declares_the_claims_file_and_its_digest():
    assert FOLDER.name == "fever" and FOLDER.location.env_var == "FEVER_DATA"
    assert [s.saves_as for s in FOLDER.sources] == ["paper_dev.jsonl"]
    manifest = Path(__file__).resolve().parents[4] / "pipeline" / "manifests" / "fever.sha256"
    assert manifest.read_text() == f"{CLAIMS_SHA256}  ./paper_dev.jsonl\n"


def trajectory(base_url: str) -> dict:
    return {
        "benchmark": "fever",
        "instance": "fever/1002",
        "options": {"wikipedia_url": base_url},
        "reset": "Claim: Mercury is a city.",
        "steps": [
            {"action": "search[Nikolaj Coster-Waldau]", "observation": ARTICLE_OBS, "reward": 0, "done": False},
            {"action": "search[Nikolaj]", "observation": SIMILAR, "reward": 0, "done": False},
            {"action": "finish[REFUTES]", "observation": "Episode finished, reward = 1\n", "reward": 1, "done": True},
        ],
    }


def test_replay_reproduces_a_recorded_trajectory(claims_dir, standin, tmp_path):
    path = tmp_path / "t.json"
    path.write_text(json.dumps(trajectory(standin.base_url)))
    result = replay_trajectory(read_trajectory(path), data_dir=str(claims_dir), limiter=TokenBucket(1000.0, 1000))
    assert (result.identical, result.message) == (True, "3 steps identical")


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (
            lambda t: t.update(reset="Claim: Mercury is a town."),
            "first observation differs: ours 'Claim: Mercury is a city.' vs recorded 'Claim: Mercury is a town.'",
        ),
        (
            lambda t: t["steps"][1].update(observation="Could not find Nikolaj."),
            "step 2 ('search[Nikolaj]'): observation differs: ours ",
        ),
        (lambda t: t["steps"][2].update(reward=0), "step 3 ('finish[REFUTES]'): reward is 1, recorded 0"),
        (lambda t: t["steps"][1].update(done=True), "step 2 ('search[Nikolaj]'): done is False, recorded True"),
        (
            lambda t: t["steps"].append({"action": "think[x]", "observation": "Nice thought."}),
            "step 4 ('think[x]'): our episode ended after step 3",
        ),
    ],
)
def test_replay_reports_the_first_difference(claims_dir, standin, change, message):
    traj = trajectory(standin.base_url)
    change(traj)
    result = replay_trajectory(traj, data_dir=str(claims_dir), limiter=TokenBucket(1000.0, 1000))
    assert result.identical is False and result.message.startswith(message)


@pytest.mark.parametrize(
    ("traj", "message"),
    [
        ({"benchmark": "robotouille"}, "not a FEVER trajectory: benchmark is 'robotouille'"),
        ({"benchmark": "fever", "steps": []}, "a FEVER trajectory needs 'instance'"),
        (
            {"benchmark": "fever", "instance": "fever/1", "options": {"colour": 1}, "steps": []},
            "'options' must be an object with keys among",
        ),
        (
            {"benchmark": "fever", "instance": "fever/1", "steps": [{"action": "x"}]},
            "step 1 needs a string 'action' and a string 'observation'",
        ),
    ],
)
def test_malformed_trajectories_are_refused(traj, message):
    with pytest.raises(TrajectoryError, match=message.replace("(", "\\(").replace("'", "'")):
        replay_trajectory(traj)


def test_a_sweeps_data_dir_option_picks_the_claims_the_planner_lists(claims_dir, tmp_path, monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    text = f"""run: dd
output: {tmp_path / "out"}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments:
  - benchmark: fever
    tasks: [all]
    limit: 2
    options: {{data_dir: "{claims_dir}", wikipedia_url: "http://127.0.0.1:9"}}
"""
    spec = parse_spec(text, "sweep.yaml")
    assert [i for i, _ in resolve_instances(spec.environments)] == ["fever/1001", "fever/1002"]
    bad = text.replace(str(claims_dir), str(tmp_path / "nowhere"))
    with pytest.raises(
        SpecError, match=r"^environments\[0\]: fever task 'all': FEVER data folder .*nowhere' \(from data_dir\) does not exist"
    ):
        resolve_instances(parse_spec(bad, "sweep.yaml").environments)
