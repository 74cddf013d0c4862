"""SWE-bench (``benchmark: swe``): repository-level issue resolution in a sandbox, as the paper runs it.

``BENCHMARK`` lists the records of a SWE-bench JSONL file (``options.instances_file``, each naming
a local git repository) and makes :class:`SweEnvironment` episodes whose commands run in a sandbox
(:mod:`workers.sandbox`). The records live in :mod:`.instances`, the tools in :mod:`.tools`, the
verdict in :mod:`.evaluate`, the model's texts in :mod:`.rules`, the gold patch as tool calls in
:mod:`.expert`.
"""

from workers.envs.swe.benchmark import BENCHMARK, SweBenchmark
from workers.envs.swe.env import SUBMIT_SENTINEL, SweEnvironment
from workers.envs.swe.evaluate import Evaluation, evaluate
from workers.envs.swe.instances import SweInstance, load_instances

__all__ = [
    "BENCHMARK",
    "SUBMIT_SENTINEL",
    "Evaluation",
    "SweBenchmark",
    "SweEnvironment",
    "SweInstance",
    "evaluate",
    "load_instances",
]
