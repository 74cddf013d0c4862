"""``recap env list/play/replay`` on FEVER through the real CLI: the paper's 200 (``--all``: every
claim), playing on the stand-in with ``--option``, replaying a FEVER trajectory live and from a
snapshot with exit 0/1/2."""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import pytest

from pipeline.cli import main
from tests.conftest import SHARED_DATA
from tests.workers.envs.fever.test_claims_replay import trajectory
from tests.workers.envs.fever.test_observations import ARTICLE_OBS
from workers.envs.fever.pages import MemoryPageStore, write_pages
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.replay import read_trajectory, replay_trajectory
from workers.envs.fever.standin import StandIn

REAL = SHARED_DATA / "fever"


@pytest.mark.skipif(not (REAL / "paper_dev.jsonl").is_file(), reason="../shared/data/fever/paper_dev.jsonl is absent")
def test_list_prints_the_paper_200_in_order_and_all_every_claim(capsys, monkeypatch):
    monkeypatch.setenv("FEVER_DATA", str(REAL))
    assert main(["env", "list", "fever"]) == 0
    out = capsys.readouterr()
    ids = out.out.splitlines()
    assert ids[:3] == ["fever/168966", "fever/226862", "fever/217220"] and ids[-1] == "fever/82886"
    assert (len(ids), out.err) == (200, "200 instances\n")
    assert main(["env", "list", "fever", "--all"]) == 0
    out = capsys.readouterr()
    assert (len(out.out.splitlines()), out.out.splitlines()[0], out.err) == (9999, "fever/91198", "9999 instances\n")


def test_list_all_on_a_small_folder_and_the_refusals(claims_dir, capsys, monkeypatch):
    monkeypatch.setenv("FEVER_DATA", str(claims_dir))
    assert main(["env", "list", "fever", "--all"]) == 0
    assert capsys.readouterr().out == "fever/1001\nfever/1002\nfever/1003\n"
    assert main(["env", "list", "fever"]) == 2
    assert capsys.readouterr().err == "recap: error: the claims file has 3 claims; the paper's set needs 7405\n"
    assert main(["env", "list", "fever", "paper", "--all"]) == 2
    assert capsys.readouterr().err == "recap: error: give a selector or --all, not both (got 'paper' and --all)\n"


def test_play_on_the_standin_with_options(claims_dir, standin: StandIn, capsys, monkeypatch):
    # the typed "Search[...]" reaches the environment as "search[...]" (the agent-facing spelling)
    monkeypatch.setattr(sys, "stdin", io.StringIO("Search[Nikolaj Coster-Waldau]\nFinish[SUPPORTS]\n"))
    argv = ["env", "play", "fever/1001", "--option", f"wikipedia_url={standin.base_url}", "--option", f"data_dir={claims_dir}"]
    assert main(argv) == 0
    claim = "Nikolaj Coster-Waldau worked with the Fox Broadcasting Company."
    assert capsys.readouterr().out == (
        f"Goal: {claim}\nClaim: {claim}\nStep 0 of 10\n> {ARTICLE_OBS}\nStep 1 of 10\n"
        "> Episode finished, reward = 1\n\nStep 2 of 10\nEpisode over after 2 steps: SUCCESS\n"
    )
    assert standin.requests == ["/w/index.php?search=Nikolaj+Coster-Waldau"]


def test_play_refuses_a_bad_option(claims_dir, capsys):
    assert main(["env", "play", "fever/1001", "--option", f"data_dir={claims_dir}", "--option", "colour=red"]) == 2
    assert capsys.readouterr().err.startswith("recap: error: unknown FEVER option(s) colour; accepted: data_dir, ")
    with pytest.raises(SystemExit) as info:
        main(["env", "play", "fever/1001", "--option", "nokey"])
    assert info.value.code == 2
    assert "argument --option: expected KEY=VALUE, got 'nokey'" in capsys.readouterr().err


def _write(tmp_path: Path, traj: dict) -> str:
    path = tmp_path / "trajectory.json"
    path.write_text(json.dumps(traj), encoding="utf-8")
    return str(path)


def test_replay_exit_0_identical_1_difference_2_malformed(claims_dir, standin: StandIn, tmp_path, capsys):
    traj = trajectory(standin.base_url)
    traj["options"]["data_dir"] = str(claims_dir)
    assert main(["env", "replay", _write(tmp_path, traj)]) == 0
    assert capsys.readouterr().out == "3 steps identical\n"
    traj["steps"][2]["reward"] = 0
    assert main(["env", "replay", _write(tmp_path, traj)]) == 1
    assert capsys.readouterr().out == "step 3 ('finish[REFUTES]'): reward is 1, recorded 0\n"
    del traj["steps"][0]["observation"]
    path = _write(tmp_path, traj)
    assert main(["env", "replay", path]) == 2
    assert capsys.readouterr().err == (
        f"recap: error: cannot replay {path}: step 1 needs a string 'action' and a string 'observation'\n"
    )


def test_replay_from_a_snapshot_reaches_no_server(claims_dir, standin: StandIn, tmp_path, capsys):
    traj = trajectory(standin.base_url)
    store = MemoryPageStore()
    live = replay_trajectory(traj, data_dir=str(claims_dir), page_store=store, limiter=TokenBucket(1000.0, 1000))
    assert live.identical
    write_pages(store.records, tmp_path / "snap" / "wiki_pages.parquet")
    served = len(standin.requests)
    path = _write(tmp_path, traj)
    argv = ["env", "replay", path, "--option", f"wikipedia=snapshot:{tmp_path / 'snap'}", "--option", f"data_dir={claims_dir}"]
    assert main(argv) == 0
    assert capsys.readouterr().out == "3 steps identical\n"
    assert len(standin.requests) == served
    # a page the snapshot lacks is an environment error (exit 2), never a live fetch
    traj["steps"].insert(0, {"action": "search[Mercury]", "observation": "?"})
    assert main(["env", "replay", _write(tmp_path, traj), *argv[3:]]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"recap: error: cannot replay {path}: snapshot_miss: ") and len(err.splitlines()) == 1
    assert len(standin.requests) == served
    assert read_trajectory(path)["benchmark"] == "fever"


def test_option_applies_to_fever_trajectories_only(tmp_path, capsys):
    path = _write(tmp_path, {"generated_environment_json": {}})
    assert main(["env", "replay", path, "--option", "wikipedia=live"]) == 2
    assert capsys.readouterr().err == (
        f"recap: error: cannot replay {path}: --option applies to FEVER trajectories only, got wikipedia\n"
    )


@pytest.mark.skipif(not (REAL / "paper_dev.jsonl").is_file(), reason="../shared/data/fever/paper_dev.jsonl is absent")
def test_the_paper_fever_sweep_estimates_the_five_methods_on_both_release_samples(capsys, monkeypatch):
    monkeypatch.setenv("FEVER_DATA", str(REAL))
    monkeypatch.setenv("COLUMNS", "100")
    example = Path(__file__).resolve().parents[4] / "examples" / "paper" / "main-fever.yaml"
    assert main(["estimate", str(example)]) == 0
    out = capsys.readouterr().out
    # main.py's 200 (seed 42) and the notebooks' 200 (seed 233) share 4 claims: 396 per method
    assert "estimate for run paper-main-fever: 1980 units" in out
    rows = [line.split("│")[1:4] for line in out.splitlines() if line.startswith("│")]
    assert [[cell.strip() for cell in row] for row in rows] == [
        [m, "gpt-4o", "396"] for m in ("recap", "react", "cot", "act", "standard")
    ]
    assert out.rstrip().endswith("run cap $500.00: fits")
