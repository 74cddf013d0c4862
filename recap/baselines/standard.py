"""Standard (I/O) prompting: CoT without the reasoning — one call returns the whole plan
``{"actions": [...]}``, executed open-loop with CoT's invalid-action and end-of-plan policy.
"""

from __future__ import annotations

from recap.baselines import prompts as P
from recap.baselines.cot import CoTAgent, PlanConfig

__all__ = ["StandardAgent", "PlanConfig"]


class StandardAgent(CoTAgent):
    """Standard (I/O): CoT without the thought; one call returns the whole plan alone."""

    style = "standard"
    expected_format = P.plan_format(False)
    with_think = False
    reply_fields = ("actions",)
