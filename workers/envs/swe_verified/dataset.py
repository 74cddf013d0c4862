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

A ``--from`` file is a user's: it is checked while it is streamed (:func:`open_rows`,
:func:`check_stream`), so its first bad record (or its 501st) is refused with ``FILE:LINE``
without reading the rest; a line is at most 16 MiB and nested at most 64 levels
(:mod:`workers.envs.user_json`: a deep one is refused before ``json`` recurses); ids, problem
statements and patches are held to the limits of a user's instances file (:func:`check_record`).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import re
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, BinaryIO, TextIO

from recap.env import DataNotFoundError, EnvError
from workers.envs import data_paths, user_json
from workers.envs.swe.instances import id_problem, problem_size_problem
from workers.envs.swe.patch_paths import patch_refusal

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
            value = user_json.loads(value)
        except ValueError as exc:  # bad JSON, or nested past the bound
            detail = "" if isinstance(exc, json.JSONDecodeError) else f" ({exc})"
            raise RecordsError(f"{where}: field {name!r} is not a JSON-encoded list{detail}") from None
    if hasattr(value, "tolist"):  # a numpy/pyarrow array from a Parquet list column
        value = value.tolist()
    if not isinstance(value, list) or not all(isinstance(t, str) and t for t in value):
        raise RecordsError(f"{where}: field {name!r} must be a list of test ids (non-empty strings)")
    return value


def check_record(raw: Any, where: str) -> dict[str, str]:
    """One record in the dataset's schema, its fields in :data:`FIELDS` order (test lists
    JSON-encoded); RecordsError naming ``where`` and the field. Its id is safe to name files and
    containers with (:func:`~workers.envs.swe.instances.id_problem`), its problem statement within
    :data:`~workers.envs.swe.instances.MAX_PROBLEM_BYTES`, its two patches inside the repository
    (:func:`~workers.envs.swe.patch_paths.patch_refusal`)."""
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
    if (problem := id_problem(iid)) is not None:
        raise RecordsError(f"{where}: instance_id {problem}")
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
    if (problem := problem_size_problem(out["problem_statement"])) is not None:
        raise RecordsError(f"{where}: field 'problem_statement' {problem}")
    for name in ("patch", "test_patch"):
        if (problem := patch_refusal(out[name])) is not None:
            raise RecordsError(f"{where}: field {name!r}: {problem}")
    return out


def check_stream(rows: Iterable[tuple[str, Any]], subset: bool, sink: Callable[[dict[str, str]], None]) -> int:
    """Check each ``(where, record)`` as it arrives and hand it to ``sink``: ids unique, no more
    than the full split's count (refused at the first record past it, the rest unread), the
    count the full split's unless ``subset``. Returns the count; RecordsError at the first bad one."""
    seen: dict[str, str] = {}
    count = 0
    for where, raw in rows:
        rec = check_record(raw, where)
        if rec["instance_id"] in seen:
            raise RecordsError(f"{where}: duplicate instance_id {rec['instance_id']!r} (first at {seen[rec['instance_id']]})")
        seen[rec["instance_id"]] = where
        count += 1
        if count > FULL_COUNT:
            raise RecordsError(f"{where}: more records than the {FULL_COUNT} of {DATASET} ({SPLIT})")
        sink(rec)
    if not count:
        raise RecordsError("no records")
    if count < FULL_COUNT and not subset:
        raise RecordsError(
            f"{count} records, not the {FULL_COUNT} of {DATASET} ({SPLIT}); pass --subset to store them as a subset"
        )
    return count


def check_records(rows: Iterable[tuple[str, Any]], subset: bool) -> list[dict[str, str]]:
    """:func:`check_stream` into a list (every record checked, ids unique, the count right)."""
    out: list[dict[str, str]] = []
    check_stream(rows, subset, out.append)
    return out


class _Digesting(io.RawIOBase):
    """A raw reader that hashes what passes through it: the sha256 of a file read once, as it is
    streamed (a FIFO cannot be read twice)."""

    def __init__(self, raw: BinaryIO) -> None:
        super().__init__()
        self._raw = raw
        self.digest = hashlib.sha256()

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        n = self._raw.readinto(buffer)  # type: ignore[attr-defined]  # an unbuffered file has it
        if n:
            self.digest.update(memoryview(buffer)[:n])
        return n or 0

    def close(self) -> None:
        self._raw.close()
        super().close()


def _jsonl_rows(f: IO[bytes], name: str) -> Iterator[tuple[str, Any]]:
    """``(name:LINE, record)`` of each non-blank line of ``f``, read a line at a time
    (:mod:`workers.envs.user_json`: a line's size and nesting bounded); RecordsError ``name:LINE: ...``."""
    try:
        for lineno, raw in user_json.records(f, name):
            yield f"{name}:{lineno}", raw
    except ValueError as exc:
        raise RecordsError(str(exc)) from None


#: rows of a Parquet copy decoded at a time
PARQUET_BATCH = 64


def _parquet_rows(path: Path) -> Iterator[tuple[str, Any]]:
    """``(name:row N, record)`` of a Parquet copy, a batch of rows at a time and only the
    dataset's columns (others are never decoded); a column nested otherwise than a list of test
    ids is refused from the schema. RecordsError for an unreadable file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        pf = pq.ParquetFile(path)
        schema = pf.schema_arrow
        for name in FIELDS:
            if name not in schema.names:
                raise RecordsError(f"{path.name}:row 1: missing field {name!r}")
            typ = schema.field(name).type
            nested = pa.types.is_nested(typ)
            if nested and not (name in ("FAIL_TO_PASS", "PASS_TO_PASS") and _string_list(typ)):
                raise RecordsError(f"{path.name}: column {name!r} is {typ}, not a string")
        i = 0
        for batch in pf.iter_batches(batch_size=PARQUET_BATCH, columns=list(FIELDS)):
            for row in batch.to_pylist():
                i += 1
                yield f"{path.name}:row {i}", row
    except (pa.ArrowException, OSError) as exc:
        raise RecordsError(f"{path} is not a readable Parquet file ({' '.join(str(exc).split())[:160]})") from None


def _string_list(typ: Any) -> bool:
    """Whether a Parquet column type is a list of strings (a test list stored as a list)."""
    import pyarrow as pa

    return bool(
        (pa.types.is_list(typ) or pa.types.is_large_list(typ))
        and (pa.types.is_string(typ.value_type) or pa.types.is_large_string(typ.value_type))
    )


@contextmanager
def open_rows(path: Path) -> Iterator[tuple[Iterator[tuple[str, Any]], Callable[[], str]]]:
    """The records of a local copy as they are read, and a function giving the sha256 of what was
    read (the whole file once the rows are exhausted): Parquet (by its magic bytes; a regular file)
    or JSONL (a regular file or a FIFO, read once). RecordsError when it cannot be read."""
    if not path.exists():
        raise RecordsError(f"{path} does not exist")
    if path.is_dir():
        raise RecordsError(f"{path} is a folder, not a file")
    try:
        digesting = _Digesting(path.open("rb", buffering=0))
    except OSError as exc:
        raise RecordsError(f"{path} cannot be read ({exc.strerror or exc})") from None
    with io.BufferedReader(digesting, buffer_size=1 << 16) as f:
        if f.peek(4)[:4] == b"PAR1":
            if not path.is_file():
                raise RecordsError(f"{path} is Parquet but not a regular file (Parquet is read from its end)")
            yield _parquet_rows(path), lambda: _sha256(path)
        else:
            yield _jsonl_rows(f, path.name), lambda: digesting.digest.hexdigest()


def read_file(path: Path) -> list[tuple[str, Any]]:
    """The records of a local copy (Parquet or JSONL), all of them, unchecked; RecordsError when
    unreadable. :func:`load_into` streams instead (:func:`open_rows`)."""
    with open_rows(path) as (rows, _digest):
        return list(rows)


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
    the records as they are read and write ``instances.jsonl`` and ``SOURCE.json`` into the empty
    folder ``dest`` (a staging folder: ``recap data fetch`` moves it into place only when this
    returns). A file is streamed: its first bad record is refused with ``FILE:LINE`` without
    reading on, and memory holds one record (or one Parquet batch) at a time. Returns the files
    written. RecordsError for bad input, LoadError when nothing can be read."""
    with (dest / INSTANCES_FILE).open("w", encoding="utf-8") as stored:

        def sink(rec: dict[str, str]) -> None:
            stored.write(json.dumps(rec, ensure_ascii=False) + "\n")

        if source is None:
            print(f"  loading {DATASET} ({SPLIT}) with the datasets library", file=out, flush=True)
            count = check_stream(read_hub(), subset, sink)
            origin, digest = f"hf://datasets/{DATASET}", ""
        else:
            path = Path(source).expanduser()
            with open_rows(path) as (rows, sha256):
                count = check_stream(rows, subset, sink)
                origin, digest = str(path.resolve()), sha256()
    meta = {
        "dataset": DATASET,
        "split": SPLIT,
        "source": origin,
        "source_sha256": digest,
        "instances": count,
        "subset": count < FULL_COUNT,
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
        with path.open("rb") as f:
            return [check_record(raw, where) for where, raw in _jsonl_rows(f, path.name)]
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
