"""Robotouille on our own clean-room engine (behaves exactly like the real engine, c8236a2e).

Instances are addressed as ``robotouille/<synchronous|asynchronous>/<task>@<layout seed>`` and read from a
Robotouille data folder (``data_dir=...`` or ``$ROBOTOUILLE_DATA``); see ``benchmark.py``.
"""

from .benchmark import BENCHMARK, RobotouilleBenchmark
from .env import RobotouilleEnv

__all__ = ["BENCHMARK", "RobotouilleBenchmark", "RobotouilleEnv"]
