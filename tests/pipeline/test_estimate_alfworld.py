"""``recap estimate`` on ALFWorld builds no game (issue 36 item 6): textworld takes seconds to build one
at reset, and the estimate of the paper's 134 games took 7.5 minutes of CPU. Its figures come from
the benchmark (:meth:`~workers.envs.alfworld.benchmark.AlfworldBenchmark.estimate_figures`); the
preflight still opens one game per task type (without building it)."""

from __future__ import annotations

import pytest

from workers.envs.alfworld.game_env import AlfworldEnvironment

SWEEP = """run: est-alfworld
output: {out}
models:
  - model: openai/gpt-4o-2024-08-06
    api_key_env: RECAP_TEST_NO_SUCH_KEY
    prices: {{input: 2.50, cached_input: 1.25, output: 10.00}}
methods: [{{method: recap}}, {{method: react}}]
environments:
  - benchmark: alfworld
    tasks: [valid_unseen]
"""


@pytest.fixture
def resets(monkeypatch):
    calls: list[str] = []
    real = AlfworldEnvironment.reset

    def counted(self):
        calls.append(self.instance_id)
        return real(self)

    monkeypatch.setattr(AlfworldEnvironment, "reset", counted)
    return calls


def test_estimate_builds_no_alfworld_game(tmp_path, capsys, resets):
    from pipeline.cli import main
    from workers.envs.registry import get_benchmark

    try:
        games = get_benchmark("alfworld").list_instances("valid_unseen")
    except Exception as exc:  # the data folder is not on this machine
        pytest.skip(f"ALFWorld data: {exc}")
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=tmp_path / "out"))
    assert main(["estimate", str(spec)]) == 0
    out = capsys.readouterr().out
    assert resets == []  # no game built, not even one per task type
    assert f"estimate for run est-alfworld: {2 * len(games)} units" in out
    rows = [line for line in out.splitlines() if line.startswith("│ recap ") or line.startswith("│ react ")]
    assert [r.split("│")[3].strip() for r in rows] == [str(len(games))] * 2


def test_the_figures_are_the_games_own_settings():
    from workers.envs.alfworld.benchmark import DEFAULT_MAX_STEPS, OPENING_CHARS
    from workers.envs.alfworld.rules import rules_text
    from workers.envs.registry import get_benchmark

    b = get_benchmark("alfworld")
    f = b.estimate_figures("alfworld/any", {"max_steps": 30, "version": "2.1.2"})
    assert (f.optimal_steps, f.max_steps, f.rules, f.observation_chars, f.demonstration) == (
        None,
        30,
        rules_text("2.1.2", 30),
        OPENING_CHARS,
        True,
    )
    assert b.estimate_figures("alfworld/any", {}).max_steps == DEFAULT_MAX_STEPS
