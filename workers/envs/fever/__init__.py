"""FEVER (claim verification over Wikipedia), as the authors' release runs it, for recap-eval.

``BENCHMARK`` lists the paper's 200 claims of ``paper_dev.jsonl`` (``all``: every claim) and makes
environments whose search answers come from live Wikipedia (any base URL: ``wikipedia_url``) or
from recorded pages (``wikipedia: snapshot:DIR``). Parsing lives in :mod:`.text`, fetching in
:mod:`.wiki`, the recorded pages in :mod:`.pages`, the shared rate limit in :mod:`.ratelimit`,
trajectory replay in :mod:`.replay`.
"""

from workers.envs.fever.benchmark import BENCHMARK, FeverBenchmark
from workers.envs.fever.env import FeverEnvironment
from workers.envs.fever.wiki import WIKI_END_REASON, WikiError

__all__ = ["BENCHMARK", "FeverBenchmark", "FeverEnvironment", "WIKI_END_REASON", "WikiError"]
