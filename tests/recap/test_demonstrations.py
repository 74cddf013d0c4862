"""Every agent renders every benchmark's demonstration by running itself on it: the scripted
replies must drive the demonstration environment to the goal in each agent's own format."""

from __future__ import annotations

import pytest

from recap.config import ABLATIONS
from recap.methods import METHODS, make_agent
from workers.envs.registry import make_env

INSTANCES = ["blocksworld/3@1", "robotouille/synchronous/0_cheese_sandwich@42", "robotouille/asynchronous/5_potato_soup@42"]


@pytest.mark.parametrize("instance", INSTANCES)
@pytest.mark.parametrize("method", [m for m in METHODS if m != "mini_swe"])  # mini_swe: no demonstration (SWE-bench)
def test_demonstration_renders_for_every_method(instance, method):
    env = make_env(instance)
    text = make_agent(method).demonstration_text(env)
    assert text.startswith("Here is a complete example of the interaction")
    assert text.endswith("[End of example: the goal was reached.]")


@pytest.mark.parametrize("ablation", list(ABLATIONS))
def test_robotouille_demonstration_renders_for_every_ablation(ablation):
    env = make_env("robotouille/synchronous/6_lettuce_tomato_cheeseburger@42")
    text = make_agent("recap", ablation=ablation).demonstration_text(env)
    assert text.count("[Example reply]") == 35
    assert ('"think"' in text) == (ablation != "no_think")
