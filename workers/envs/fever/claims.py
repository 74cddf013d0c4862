"""The FEVER claims: where ``paper_dev.jsonl`` is, how it is read, and which 200 the paper ran.

The release reads ``data/paper_dev.jsonl`` line by line into ``(claim, label)`` pairs, so a claim's
index is its 0-based line number (fever-recap/hotpotqa/wrappers.py:143-152). Its runner shuffles
the indices ``0..7404`` - not the file's 9,999 lines - with ``random.Random(42)`` and runs the first
``test_count`` = 200 (fever-recap/main.py:26-40, conf/config.toml: seed 42, test_count 200);
:func:`paper_indices` reproduces that list. The ReAct and Act notebooks shuffle the same range
with ``random.Random(233)`` instead (fever-recap/React.ipynb and baseline_act.ipynb, cell 4:
``random.Random(233).shuffle(idxs)``, ``for i in idxs[0:200]``): the option ``sample_seed``
picks which sample ``paper`` means (:data:`NOTEBOOK_SEED` for the notebooks' 200; the two
samples share 4 claims). CoT and Standard read the seed from ``conf/config.toml`` (42). Instance ids are ``fever/<claim id>`` (the ``id`` field).
The folder is found by the shared rule of ``workers/envs/data_paths.py``: ``data_dir``, else
``$FEVER_DATA``, else recap-eval's cache, else ``<checkout>/../shared/data/fever``.
"""

from __future__ import annotations

import json
import os
import random
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from recap.env import DataNotFoundError, EnvError, UnknownInstanceError
from workers.envs import data_paths

BENCHMARK_NAME = "fever"
ENV_VAR = "FEVER_DATA"
CLAIMS_FILE = "paper_dev.jsonl"
#: the release's shuffled index range (main.py:32), its seed and its count (conf/config.toml)
PAPER_INDEX_RANGE = 7405
PAPER_SEED = 42
#: the seed of the ReAct/Act notebooks' shuffle (React.ipynb / baseline_act.ipynb cell 4)
NOTEBOOK_SEED = 233
PAPER_COUNT = 200
LABELS = ("SUPPORTS", "REFUTES", "NOT ENOUGH INFO")


class ClaimsFileError(EnvError):
    """``paper_dev.jsonl`` exists but a line is not a claim (bad JSON, a missing field, a repeated id)."""


#: how FEVER's page ids spell brackets and colons (``Soul_Food_-LRB-film-RRB-``)
_PAGE_ID_TOKENS = {"-LRB-": "(", "-RRB-": ")", "-LSB-": "[", "-RSB-": "]", "-LCB-": "{", "-RCB-": "}", "-COLON-": ":"}


@dataclass(frozen=True)
class Claim:
    """One claim: its line number in the file (the release's index), id, text and label, and the
    titles of the Wikipedia pages its evidence cites, in order (none for NOT ENOUGH INFO)."""

    index: int
    id: int
    claim: str
    label: str
    evidence_pages: tuple[str, ...] = ()

    @property
    def instance_id(self) -> str:
        return f"{BENCHMARK_NAME}/{self.id}"


def _invalid(path: Path, source: str, problem: str) -> str:
    if problem == "absent":
        return f"FEVER data folder {str(path)!r} (from {source}) does not exist"
    return f"{str(path)!r} (from {source}) is not a FEVER data folder: {CLAIMS_FILE} is missing"


def _missing(rungs: list[data_paths.Rung]) -> str:
    return (
        f"no FEVER data folder: pass data_dir=... or set {ENV_VAR} to a folder holding {CLAIMS_FILE}, "
        f"or run `recap data fetch fever` (looked in {data_paths.describe_probed(rungs)})"
    )


#: how the shared resolver recognises a FEVER folder
LOCATION = data_paths.DataLocation(
    name=BENCHMARK_NAME,
    title="FEVER",
    env_var=ENV_VAR,
    marker=CLAIMS_FILE,
    upstream_note="none (the FEVER release is a set of files, not a package with a cache)",
)


def resolve_data_dir(data_dir: str | os.PathLike[str] | None = None) -> Path:
    """The FEVER data folder by the shared rule; raises DataNotFoundError naming where it looked."""
    path, _rung = data_paths.resolve(LOCATION, data_dir, invalid=_invalid, missing=_missing)
    return path


def page_title(page_id: str) -> str:
    """A FEVER page id as a Wikipedia title: ``Soul_Food_-LRB-film-RRB-`` -> ``Soul Food (film)``."""
    for token, char in _PAGE_ID_TOKENS.items():
        page_id = page_id.replace(token, char)
    return page_id.replace("_", " ")


def evidence_pages(evidence: object) -> tuple[str, ...]:
    """The distinct page titles an ``evidence`` field cites, first cited first (sets of
    ``[annotation, evidence id, page id, sentence]``; null pages skipped)."""
    titles: list[str] = []
    for group in evidence if isinstance(evidence, list) else []:
        for item in group if isinstance(group, list) else []:
            if isinstance(item, list) and len(item) > 2 and isinstance(item[2], str):
                title = page_title(item[2])
                if title not in titles:
                    titles.append(title)
    return tuple(titles)


def _parse_line(path: Path, index: int, line: str) -> Claim:
    try:
        row = json.loads(line)
        return Claim(
            index=index,
            id=int(row["id"]),
            claim=str(row["claim"]),
            label=str(row["label"]),
            evidence_pages=evidence_pages(row.get("evidence")),
        )
    except (ValueError, KeyError, TypeError) as exc:
        raise ClaimsFileError(f"{str(path)!r} line {index + 1} is not a FEVER claim: {type(exc).__name__}: {exc}") from None


@lru_cache(maxsize=4)
def _load(path: Path, mtime_ns: int) -> tuple[Claim, ...]:
    with path.open(encoding="utf-8") as fh:
        claims = tuple(_parse_line(path, i, line) for i, line in enumerate(fh))  # wrappers.py:144-152: one claim a line
    seen: set[int] = set()
    for c in claims:
        if c.id in seen:
            raise ClaimsFileError(f"{str(path)!r}: claim id {c.id} appears more than once")
        seen.add(c.id)
    return claims


def load_claims(folder: Path) -> tuple[Claim, ...]:
    """Every claim of ``folder/paper_dev.jsonl`` in file order (cached while the file is unchanged)."""
    path = folder / CLAIMS_FILE
    try:
        stat = path.stat()
    except FileNotFoundError:
        raise DataNotFoundError(f"FEVER claims file {str(path)!r} does not exist") from None
    return _load(path, stat.st_mtime_ns)


def check_sample_seed(seed: object) -> int:
    """``seed`` when it is a non-negative integer (the ``sample_seed`` option), else ValueError."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(
            f"sample_seed must be a non-negative integer (42: ReCAP/CoT/Standard, 233: the ReAct/Act notebooks), got {seed!r}"
        )
    return seed


def paper_indices(seed: int = PAPER_SEED) -> list[int]:
    """The release's 200 claim indices in its order: ``range(7405)`` shuffled by
    ``random.Random(seed)``, the first 200 (main.py:32-40 with seed 42; the ReAct/Act notebooks'
    cell 4 with 233)."""
    idxs = list(range(PAPER_INDEX_RANGE))
    random.Random(check_sample_seed(seed)).shuffle(idxs)
    return idxs[:PAPER_COUNT]


def select(claims: tuple[Claim, ...], selector: str | None, sample_seed: int = PAPER_SEED) -> list[Claim]:
    """``None``/``"paper"``: the 200 of the release's shuffle with ``sample_seed`` (42: main.py,
    233: the ReAct/Act notebooks) in its order; ``"all"``: every claim in file order."""
    if selector in (None, "", "paper"):
        if len(claims) < PAPER_INDEX_RANGE:
            raise ClaimsFileError(f"the claims file has {len(claims)} claims; the paper's set needs {PAPER_INDEX_RANGE}")
        return [claims[i] for i in paper_indices(sample_seed)]
    if selector == "all":
        return list(claims)
    raise UnknownInstanceError(f"unknown FEVER selector {selector!r}; selectors: paper (the paper's 200, default), all")


def find_claim(claims: tuple[Claim, ...], instance_id: str) -> Claim:
    """The claim of ``fever/<claim id>``; UnknownInstanceError for an id the file does not hold."""
    bench, _, rest = instance_id.partition("/")
    if bench != BENCHMARK_NAME or not rest.isdigit():
        raise UnknownInstanceError(f"a FEVER instance id looks like fever/<claim id>, got {instance_id!r}")
    wanted = int(rest)
    for claim in claims:
        if claim.id == wanted:
            return claim
    raise UnknownInstanceError(f"no FEVER claim with id {wanted} in {CLAIMS_FILE}")
