"""Every evaluation game is winnable by replaying its expert walkthrough, in both versions."""

from __future__ import annotations

import pytest

from tests.workers.envs.alfworld.helpers import DATA, DATA_2_1_2, win_by_expert
from workers.envs.alfworld import AlfworldBenchmark

BENCH = AlfworldBenchmark(DATA)
IDS = BENCH.list_instances()


@pytest.mark.slow
@pytest.mark.parametrize("version", ["2.1.1", "2.1.2"])
@pytest.mark.parametrize("instance_id", IDS)
def test_expert_wins(instance_id, version):
    env = BENCH.make(instance_id, version=version, data_dir_2_1_2=DATA_2_1_2)
    try:
        plan = win_by_expert(env)
        other_wording = "move " if version == "2.1.1" else "put "
        assert not any(a.startswith(other_wording) for a in plan)
    finally:
        env.close()


@pytest.mark.slow
def test_the_slow_suite_covers_all_134_games():
    assert len(IDS) == 134
