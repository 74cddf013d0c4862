"""SWE-bench Verified (``benchmark: swe-verified``): the 500 human-validated instances, each in the harness's image.

The dataset is stored by ``recap data fetch swebench-verified`` (:mod:`.dataset`); each instance
runs in the coding environment of ``workers/envs/swe`` inside the SWE-bench harness's
per-instance image (:mod:`.images`), its test command the harness's (:mod:`.harness`).
"""

from workers.envs.swe_verified.benchmark import BENCHMARK, VerifiedBenchmark
from workers.envs.swe_verified.env import VerifiedEnvironment

__all__ = ["BENCHMARK", "VerifiedBenchmark", "VerifiedEnvironment"]
