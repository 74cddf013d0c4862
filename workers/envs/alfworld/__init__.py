"""ALFWorld (text-only, the real ``alfworld`` 0.4.2 games on textworld 1.7.0) for recap-eval.

``BENCHMARK`` lists the 134 ``eval_out_of_distribution`` games and makes environments. Nothing
here imports ``alfworld``/``textworld`` until a game is opened, so listing ids, the rules and the
demonstrations work without the optional extra installed.
"""

from workers.envs.alfworld.benchmark import BENCHMARK, AlfworldBenchmark
from workers.envs.alfworld.game_env import AlfworldEnvironment
from workers.envs.alfworld.replay import RecordedStep, Recording, ReplayEnvironment

__all__ = [
    "BENCHMARK",
    "AlfworldBenchmark",
    "AlfworldEnvironment",
    "RecordedStep",
    "Recording",
    "ReplayEnvironment",
]
