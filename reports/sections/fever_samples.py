"""Which FEVER claims make each of the release's two 200-claim samples, loaded into ``fever_samples``.

Why the report needs it: the paper's FEVER numbers come from two different samples of
``paper_dev.jsonl``. ReCAP, CoT and Standard ran the 200 of ``fever-recap/main.py``'s shuffle
(``random.Random(42)`` over the indices 0..7404, conf/config.toml ``seed = 42``); ReAct and Act
ran the notebooks' (``random.Random(233)``, React.ipynb / baseline_act.ipynb cell 4). A sweep runs
both (``sample_seed``); an arm's number stands beside the paper's only over the paper's sample for
its method (:data:`reports.paper.FEVER_SAMPLE_SEED`). The shuffle is the same few lines as
``workers.envs.fever.claims.paper_indices`` (the report reads no workers code; a test checks the
two agree); the claims file is the one the runs read: ``$FEVER_DATA``, else
``../shared/data/fever`` beside the checkout. Without it the table stays empty and the report
says that the sample cannot be told.
"""

from __future__ import annotations

import json
import os
import random
from pathlib import Path

import duckdb

CLAIMS_FILE = "paper_dev.jsonl"
#: the release's shuffled index range and count (fever-recap/main.py:32-40)
INDEX_RANGE = 7405
COUNT = 200
SEEDS = (42, 233)


def sample_indices(seed: int) -> list[int]:
    """The 200 claim indices of the release's shuffle with ``seed``, in its order."""
    idxs = list(range(INDEX_RANGE))
    random.Random(seed).shuffle(idxs)
    return idxs[:COUNT]


def claims_file() -> Path | None:
    """``paper_dev.jsonl`` of ``$FEVER_DATA``, else of ``../shared/data/fever`` beside the checkout; None when absent."""
    for folder in (os.environ.get("FEVER_DATA"), Path(__file__).resolve().parents[3] / "shared" / "data" / "fever"):
        if folder and (Path(folder) / CLAIMS_FILE).is_file():
            return Path(folder) / CLAIMS_FILE
    return None


def sample_rows(path: Path) -> list[tuple[str, int]]:
    """(instance id, sample seed) for every claim of both samples (a claim in both: two rows)."""
    with path.open(encoding="utf-8") as fh:
        ids = [f"fever/{json.loads(line)['id']}" for line in fh]
    if len(ids) < INDEX_RANGE:
        return []
    return [(ids[i], seed) for seed in SEEDS for i in sample_indices(seed)]


def load_fever_samples(con: duckdb.DuckDBPyConnection) -> bool:
    """Fill ``fever_samples`` (reports/sql/views.sql) once per connection when a run holds FEVER
    episodes and the claims file is found; whether it holds rows."""
    if (con.execute("SELECT count(*) FROM fever_samples").fetchone() or (0,))[0]:
        return True
    if not (con.execute("SELECT count(*) FROM outcomes WHERE benchmark = 'fever'").fetchone() or (0,))[0]:
        return False
    path = claims_file()
    rows = sample_rows(path) if path is not None else []
    if rows:
        con.executemany("INSERT INTO fever_samples VALUES (?, ?)", rows)
    return bool(rows)
