"""The paper's baselines on the same interface as ReCAP: ReAct, Act, CoT, Standard (sequential
prompting) and ADaPT (hierarchical prompting). Each is an :class:`recap.agent.Agent` that talks
to the model only through :class:`recap.runtime.Conversation` and to the environment only
through :class:`recap.runtime.EnvDriver`.
"""

from recap.baselines.act import ActAgent, ActConfig
from recap.baselines.adapt import ADaPTAgent, ADaPTConfig
from recap.baselines.cot import CoTAgent, PlanConfig
from recap.baselines.react import ReActAgent, ReActConfig
from recap.baselines.standard import StandardAgent

__all__ = [
    "ADaPTAgent",
    "ADaPTConfig",
    "ActAgent",
    "ActConfig",
    "CoTAgent",
    "PlanConfig",
    "ReActAgent",
    "ReActConfig",
    "StandardAgent",
]
