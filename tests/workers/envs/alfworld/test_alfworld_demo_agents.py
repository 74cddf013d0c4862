"""The demonstrations rendered by the real agents (recap/): each one reaches its goal and the
agent uses exactly the scripted replies, in both game-file versions."""

from __future__ import annotations

import pytest

from recap.baselines.act import ActAgent
from recap.baselines.react import ReActAgent, ReActConfig
from recap.config import ReCAPConfig
from recap.recap_agent import ReCAPAgent
from recap.scripted import ScriptedClient
from workers.envs.alfworld.demos import demonstration_for
from workers.envs.alfworld.task_types import TASK_TYPES

AGENTS = {
    "recap": lambda: ReCAPAgent(ReCAPConfig()),
    "react": lambda: ReActAgent(ReActConfig()),
    "act": lambda: ActAgent(ReActConfig()),
}


@pytest.mark.parametrize("version", ["2.1.1", "2.1.2"])
@pytest.mark.parametrize("style", list(AGENTS))
@pytest.mark.parametrize("short", list(TASK_TYPES))
def test_agent_plays_the_demonstration(short, style, version):
    demo = demonstration_for(short, version)
    client = ScriptedClient(demo.replies[style])
    result = AGENTS[style]().run(demo.make_env(), client, episode_id="t", emit=lambda r: None, demonstration=False)
    assert (result.success, result.end_reason, result.error) == (True, "success", None)
    assert client.remaining == 0


def test_rendered_transcript_holds_the_recorded_text():
    text = ReCAPAgent(ReCAPConfig()).render_demonstration(demonstration_for("heat"))
    assert "You arrive at loc 16. The fridge 1 is closed." in text
    assert '"subtasks": ["put potato 1 in/on diningtable 1"]' in text
