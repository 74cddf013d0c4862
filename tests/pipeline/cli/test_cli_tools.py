"""``recap env list/play/replay`` and ``recap estimate`` (no Ray, no model)."""

from __future__ import annotations

import io
import re
import sys

from pipeline.cli import main
from recap.blocksworld import BENCHMARK
from workers.envs.robotouille import benchmark as robotouille_benchmark


def test_env_list(capsys):
    assert main(["env", "list", "blocksworld", "4"]) == 0
    out = capsys.readouterr()
    assert out.out.splitlines() == ["blocksworld/4@1", "blocksworld/4@2", "blocksworld/4@3"]
    assert out.err.strip() == "3 instances"


def test_env_list_unknown_selector(capsys):
    assert main(["env", "list", "blocksworld", "11"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "recap: error: no blocksworld instance matches '11'; sizes [3, 4, 5], e.g. blocksworld/3@1"
    ]


def test_env_play_by_number_and_by_text(capsys, monkeypatch):
    env = BENCHMARK.make("blocksworld/3@1")
    start = env.reset()
    plan = env.expert_plan()
    # first action by its number in the printed list, the rest by their text
    lines = [str(start.valid_actions.index(plan[0]) + 1), "not an action"] + plan[1:]
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n".join(lines) + "\n"))
    assert main(["env", "play", "blocksworld/3@1"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"Goal: {start.goal}\n")
    assert "Invalid action: 'not an action' is not a valid action here" in out
    assert out.rstrip().endswith(f"Episode over after {len(plan)} steps: SUCCESS")


def test_env_replay_delegates_and_sets_the_exit_status(tmp_path, capsys, monkeypatch):
    calls = []

    def replay_file(path):
        calls.append(path)
        return (path.endswith("good.json"), f"replayed {path}")

    # a file without a "benchmark" field is the real Robotouille engine's: its benchmark replays it
    monkeypatch.setattr(robotouille_benchmark, "replay_file", replay_file)
    assert main(["env", "replay", "good.json"]) == 0
    assert main(["env", "replay", "bad.json"]) == 1
    assert calls == ["good.json", "bad.json"]
    assert capsys.readouterr().out.splitlines() == ["replayed good.json", "replayed bad.json"]


def test_estimate_ranges(tmp_path, capsys):
    spec = tmp_path / "sweep.yaml"
    spec.write_text(f"""run: est
output: {tmp_path / "never"}
models:
  - model: gpt-4o
  - model: offline/expert
methods: [{{method: recap}}, {{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3"]}}]
run_cap_usd: 1000
""")
    assert main(["estimate", str(spec)]) == 0
    out = capsys.readouterr().out
    assert "estimate for run est: 12 units" in out
    assert "offline/expert (test double)" in out
    m = re.search(r"total: 12 units, ([\d,]+) - ([\d,]+) calls, \$([\d.]+) - \$([\d.]+)", out)
    assert m is not None
    lo_calls, hi_calls, lo_cost, hi_cost = (float(g.replace(",", "")) for g in m.groups())
    assert 0 < lo_calls <= hi_calls and 0 < lo_cost <= hi_cost
    assert "run cap $1000.00: fits" in out
    assert not (tmp_path / "never").exists()


def test_env_replay_goes_to_the_benchmark_the_file_names(tmp_path, capsys):
    """``recap env replay`` asks the benchmark a trajectory names (Benchmark.replay_file): one
    without recorded trajectories, or a name nothing registers, is a one-line refusal, exit 2."""
    none = tmp_path / "blocks.json"
    none.write_text('{"benchmark": "blocksworld", "steps": []}')
    unknown = tmp_path / "nowhere.json"
    unknown.write_text('{"benchmark": "nowhere", "steps": []}')
    assert main(["env", "replay", str(none)]) == 2
    assert main(["env", "replay", str(unknown)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == f"recap: error: cannot replay {none}: blocksworld has no recorded-trajectory replay"
    assert err[1].startswith(f"recap: error: cannot replay {unknown}: unknown benchmark 'nowhere'; known: blocksworld, ")
    assert len(err) == 2
