"""The real agents, driven by the offline expert through the gateway: every call is recorded."""

from __future__ import annotations

import pytest

from tests.doubles.agent_episodes import assert_every_call_recorded, episode_rows, play
from workers.gateway.blocking import BlockingGateway
from workers.llm.providers import DeploymentConfig


@pytest.mark.parametrize("method", ["recap", "react", "cot"])
def test_expert_drives_each_agent_to_success_and_every_call_is_recorded(run_dir, method):
    with BlockingGateway(DeploymentConfig(model="offline/expert"), run_dir=run_dir) as gw:
        result = play(method, "blocksworld/3@1", gw, f"{method}-ep", offline=True)
    assert (result.end_reason, result.success) == ("success", True)
    rows = episode_rows(run_dir, f"{method}-ep")
    assert_every_call_recorded(result, rows)
    assert {(r["model"], r["test_double"], r["status"]) for r in rows} == {("offline/expert", True, "ok")}


def test_injected_faults_reach_the_agent_and_are_recorded(run_dir):
    cfg = DeploymentConfig(
        model="offline/expert", offline_options={"seed": 5, "malformed_json_rate": 0.25, "invalid_action_rate": 0.25}
    )
    with BlockingGateway(cfg, run_dir=run_dir) as gw:
        result = play("recap", "blocksworld/3@2", gw, "faulty", offline=True)
    assert result.json_repairs >= 1
    rows = episode_rows(run_dir, "faulty")
    assert_every_call_recorded(result, rows)
    assert "repair" in {r["purpose"] for r in rows}
