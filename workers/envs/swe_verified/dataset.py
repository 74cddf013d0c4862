"""SWE-bench Verified's records: read them (a local Parquet/JSONL copy or the Hugging Face Hub), check them, store them.

The dataset is ``princeton-nlp/SWE-bench_Verified``, split ``test``: 500 instances, each with the
fields of :data:`FIELDS` (all strings; ``FAIL_TO_PASS``/``PASS_TO_PASS`` JSON-encoded lists of test
ids, as the dataset ships them). ``recap data fetch swebench-verified`` loads it with the
``datasets`` library (imported only then: no machine of this project reaches the Hub, so that path
fails with one line naming ``--from``) or from ``--from FILE``, checks every record
(:func:`check_records`) and writes the folder: ``instances.jsonl`` (the records, the dataset's
order and fields) and ``SOURCE.json`` (where they came from, how many, whether it is a subset).
The repository cannot pin the folder's digest (its bytes come from a dataset this machine cannot
reach), so the folder carries its own ``MANIFEST.sha256`` written at fetch time, which
``recap data check`` verifies.

A file with fewer than 500 records is refused unless ``--subset`` is given, and then recorded as
a subset (``SOURCE.json`` ``"subset": true``), so a partial copy is never reported as the benchmark.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from recap.env import DataNotFoundError, EnvError
from workers.envs import data_paths

DATASET = "princeton-nlp/SWE-bench_Verified"
SPLIT = "test"
#: instances of the full test split
FULL_COUNT = 500
FOLDER_NAME = "swebench-verified"
ENV_VAR = "SWEBENCH_VERIFIED_DATA"
INSTANCES_FILE = "instances.jsonl"
SOURCE_FILE = "SOURCE.json"
#: the dataset's fields, in its order
FIELDS = (
    "repo",
    "instance_id",
    "base_commit",
    "patch",
    "test_patch",
    "problem_statement",
    "hints_text",
    "created_at",
    "version",
    "FAIL_TO_PASS",
    "PASS_TO_PASS",
    "environment_setup_commit",
    "difficulty",
)
#: ``owner__repo-NUMBER`` (the harness's ids: ``django__django-11099``)
ID_PATTERN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9_.-]*?)__([A-Za-z0-9][A-Za-z0-9_.-]*)-([0-9]+)$")


class RecordsError(ValueError):
    """The input is not SWE-bench Verified records (bad JSON, a missing or mistyped field, a bad or
    repeated id, a wrong count): one line; ``recap data fetch`` exits 2 and writes nothing."""


class LoadError(RuntimeError):
    """The records cannot be obtained (no ``datasets`` library, the Hub unreachable): one line;
    ``recap data fetch`` exits 1."""


def _test_list(where: str, name: str, value: Any) -> list[str]:
    """A test list field as a list of ids (the dataset's JSON-encoded string, or a list in a Parquet copy)."""
    if isinstance(value, str):
        try:
            value = json.loads(value)
        except json.JSONDecodeError:
            raise RecordsError(f"{where}: field {name!r} is not a JSON-encoded list") from None
    if hasattr(value, "tolist"):  # a numpy/pyarrow array from a Parquet list column
        value = value.tolist()
    if not isinstance(value, list) or not all(isinstance(t, str) and t for t in value):
        raise RecordsError(f"{where}: field {name!r} must be a list of test ids (non-empty strings)")
    return value


def check_record(raw: Any, where: str) -> dict[str, str]:
    """One record in the dataset's schema, its fields in :data:`FIELDS` order (test lists
    JSON-encoded); RecordsError naming ``where`` and the field."""
    if not isinstance(raw, dict):
        raise RecordsError(f"{where}: a record must be an object, got {type(raw).__name__}")
    missing = [f for f in FIELDS if f not in raw]
    if missing:
        raise RecordsError(f"{where}: missing field {missing[0]!r}")
    out: dict[str, str] = {}
    for name in FIELDS:
        value = raw[name]
        if name in ("FAIL_TO_PASS", "PASS_TO_PASS"):
            out[name] = json.dumps(_test_list(where, name, value))
        elif not isinstance(value, str):
            raise RecordsError(f"{where}: field {name!r} must be a string, got {type(value).__name__}")
        else:
            out[name] = value
    iid = out["instance_id"]
    m = ID_PATTERN.match(iid)
    if m is None:
        raise RecordsError(f"{where}: instance_id {iid!r} is not of the form owner__repo-NUMBER")
    if out["repo"] != f"{m.group(1)}/{m.group(2)}":
        raise RecordsError(f"{where}: instance_id {iid!r} does not belong to repo {out['repo']!r}")
    if not re.fullmatch(r"[0-9a-f]{7,40}", out["base_commit"]):
        raise RecordsError(f"{where}: field 'base_commit' must be a commit hash, got {out['base_commit']!r}")
    if not json.loads(out["FAIL_TO_PASS"]):
        raise RecordsError(f"{where}: field 'FAIL_TO_PASS' is empty (an instance needs a test its fix makes pass)")
    if not out["patch"].strip():
        raise RecordsError(f"{where}: field 'patch' is empty")
    return out


def check_records(rows: list[tuple[str, Any]], subset: bool) -> list[dict[str, str]]:
    """Every ``(where, record)`` checked, ids unique, the count the full split's unless ``subset``."""
    out: list[dict[str, str]] = []
    seen: dict[str, str] = {}
    for where, raw in rows:
        rec = check_record(raw, where)
        if rec["instance_id"] in seen:
            raise RecordsError(f"{where}: duplicate instance_id {rec['instance_id']!r} (first at {seen[rec['instance_id']]})")
        seen[rec["instance_id"]] = where
        out.append(rec)
    if not out:
        raise RecordsError("no records")
    if len(out) > FULL_COUNT:
        raise RecordsError(f"{len(out)} records, more than the {FULL_COUNT} of {DATASET} ({SPLIT})")
    if len(out) < FULL_COUNT and not subset:
        raise RecordsError(
            f"{len(out)} records, not the {FULL_COUNT} of {DATASET} ({SPLIT}); pass --subset to store them as a subset"
        )
    return out


def _jsonl_rows(path: Path) -> Iterator[tuple[str, Any]]:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise RecordsError(f"{path} is not UTF-8 text (JSONL) nor Parquet") from None
    for lineno, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        try:
            yield f"{path.name}:{lineno}", json.loads(line)
        except json.JSONDecodeError as exc:
            raise RecordsError(f"{path.name}:{lineno}: not valid JSON ({exc.msg} at column {exc.colno})") from None


def _parquet_rows(path: Path) -> Iterator[tuple[str, Any]]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        raise RecordsError(f"{path} is not a readable Parquet file ({' '.join(str(exc).split())[:160]})") from None
    for i, row in enumerate(table.to_pylist(), 1):
        yield f"{path.name}:row {i}", row


def read_file(path: Path) -> list[tuple[str, Any]]:
    """The records of a local copy: Parquet (by its magic bytes) or JSONL; RecordsError when unreadable."""
    if not path.is_file():
        raise RecordsError(f"{path} is not a file")
    with path.open("rb") as f:
        head = f.read(4)
    return list(_parquet_rows(path) if head == b"PAR1" else _jsonl_rows(path))


def read_hub() -> list[tuple[str, Any]]:
    """The records from the Hugging Face Hub through ``datasets``; LoadError (one line) when it cannot."""
    hint = f"download {DATASET} ({SPLIT}) elsewhere and pass --from FILE (Parquet or JSONL)"
    try:
        import datasets
    except ImportError:
        raise LoadError(f"the datasets library is not installed (pip install 'recap-eval[swe]'); or {hint}") from None
    try:
        import huggingface_hub.utils

        datasets.utils.logging.set_verbosity_error()  # its retries' warnings are not our one line
        huggingface_hub.utils.logging.set_verbosity_error()
        ds = datasets.load_dataset(DATASET, split=SPLIT)
    except Exception as exc:  # the library raises many kinds (connection, hub, file-system errors)
        reason = " ".join(str(exc).split())[:160] or type(exc).__name__
        raise LoadError(f"cannot load {DATASET} from the Hugging Face Hub ({reason}); {hint}") from None
    return [(f"{DATASET}:row {i}", dict(row)) for i, row in enumerate(ds, 1)]


def load_into(source: str | None, subset: bool, dest: Path, out: TextIO) -> list[str]:
    """``recap data fetch``'s load for this folder: read ``source`` (a file; None: the Hub), check
    the records and write ``instances.jsonl`` and ``SOURCE.json`` into the empty folder ``dest``.
    Returns the files written. RecordsError for bad input, LoadError when nothing can be read."""
    if source is None:
        print(f"  loading {DATASET} ({SPLIT}) with the datasets library", file=out, flush=True)
        rows, origin, digest = read_hub(), f"hf://datasets/{DATASET}", ""
    else:
        path = Path(source).expanduser()
        rows = read_file(path)
        origin, digest = str(path.resolve()), _sha256(path)
    records = check_records(rows, subset)
    lines = "".join(json.dumps(r, ensure_ascii=False) + "\n" for r in records)
    (dest / INSTANCES_FILE).write_text(lines, encoding="utf-8")
    meta = {
        "dataset": DATASET,
        "split": SPLIT,
        "source": origin,
        "source_sha256": digest,
        "instances": len(records),
        "subset": len(records) < FULL_COUNT,
    }
    (dest / SOURCE_FILE).write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    return [INSTANCES_FILE, SOURCE_FILE]


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            digest.update(chunk)
    return digest.hexdigest()


# -- reading the stored folder ------------------------------------------------------------------
def _invalid(path: Path, source: str, problem: str) -> str:
    if problem == "absent":
        return f"SWE-bench Verified data folder {str(path)!r} (from {source}) does not exist"
    return f"{str(path)!r} (from {source}) is not a SWE-bench Verified data folder: {INSTANCES_FILE} is missing"


def _missing(rungs: list[data_paths.Rung]) -> str:
    return (
        f"no SWE-bench Verified data folder: run `recap data fetch {FOLDER_NAME}` (or `--from FILE`), "
        f"or set {ENV_VAR} (looked in {data_paths.describe_probed(rungs)})"
    )


#: how the shared resolver recognises the folder
LOCATION = data_paths.DataLocation(
    name=FOLDER_NAME,
    title="SWE-bench Verified",
    env_var=ENV_VAR,
    marker=INSTANCES_FILE,
    upstream_note="none (the datasets library's cache holds Arrow files, not this folder)",
)


def resolve_data_dir(data_dir: str | os.PathLike[str] | None = None) -> Path:
    """The folder by the shared rule; DataNotFoundError naming where it looked."""
    path, _rung = data_paths.resolve(LOCATION, data_dir, invalid=_invalid, missing=_missing)
    return path


@dataclass(frozen=True)
class Source:
    """``SOURCE.json``: where the stored records came from and whether they are a subset."""

    instances: int
    subset: bool
    source: str


def read_source(folder: Path) -> Source:
    """The folder's ``SOURCE.json`` (a folder without one counts as a subset of unknown origin)."""
    try:
        raw = json.loads((folder / SOURCE_FILE).read_text(encoding="utf-8"))
        return Source(int(raw["instances"]), bool(raw["subset"]), str(raw["source"]))
    except (OSError, ValueError, KeyError, TypeError):
        return Source(-1, True, "unknown")


def read_folder(folder: Path) -> list[dict[str, str]]:
    """The stored records of ``folder`` in order; EnvError (one line) for a file ``fetch`` did not write."""
    path = folder / INSTANCES_FILE
    try:
        rows = list(_jsonl_rows(path))
        return [check_record(raw, where) for where, raw in rows]
    except (RecordsError, OSError) as exc:
        raise EnvError(f"{path}: {exc}; fetch it again with `recap data fetch {FOLDER_NAME}`") from None


def records(data_dir: str | os.PathLike[str] | None = None) -> list[dict[str, str]]:
    """The stored records of the folder the shared rule finds (read once per file version)."""
    folder = resolve_data_dir(data_dir)
    path = folder / INSTANCES_FILE
    st = path.stat()
    return list(_cached(str(path.resolve()), st.st_size, st.st_mtime_ns))


_CACHE: dict[tuple[str, int, int], tuple[dict[str, str], ...]] = {}


def _cached(path: str, size: int, mtime_ns: int) -> tuple[dict[str, str], ...]:
    key = (path, size, mtime_ns)
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = tuple(read_folder(Path(path).parent))
    return _CACHE[key]


__all__ = [
    "DATASET",
    "FIELDS",
    "FULL_COUNT",
    "DataNotFoundError",
    "LoadError",
    "RecordsError",
    "check_record",
    "check_records",
    "load_into",
    "read_file",
    "records",
    "resolve_data_dir",
]
