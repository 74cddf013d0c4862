"""SWE-bench Verified fixtures: a small file in the dataset's schema built from the swe example tasks."""

from __future__ import annotations

import json
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from workers.envs.swe.examples import Fixtures, make_fixtures
from workers.envs.swe_verified.dataset import FIELDS

#: the example tasks the dataset file holds, in its order
NAMES = ("offbyone", "format", "twofiles")


def verified_records(fixtures: Fixtures) -> list[dict[str, str]]:
    """The example tasks as SWE-bench Verified records (the dataset's 13 fields, ids ``fixture__<name>-1``)."""
    out = []
    for line in fixtures.tasks_file.read_text().splitlines():
        r = json.loads(line)
        r.update(hints_text="", created_at="2024-01-01T00:00:00Z", environment_setup_commit=r["base_commit"])
        r["difficulty"] = "<15 min fix"
        out.append({k: r[k] for k in FIELDS})
    return out


@pytest.fixture(scope="session")
def verified_fixtures(tmp_path_factory: pytest.TempPathFactory) -> Fixtures:
    return make_fixtures(tmp_path_factory.mktemp("verified") / "fx", NAMES)


@pytest.fixture
def records(verified_fixtures: Fixtures) -> list[dict[str, str]]:
    return verified_records(verified_fixtures)


def write_jsonl(path: Path, rows: list[object]) -> Path:
    """``rows`` one JSON value a line."""
    path.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    return path


@pytest.fixture
def cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """recap-eval's cache in a temporary folder (where ``fetch`` writes and the search looks)."""
    monkeypatch.setenv("RECAP_EVAL_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("SWEBENCH_VERIFIED_DATA", raising=False)
    return tmp_path / "cache" / "data" / "swebench-verified"


@contextmanager
def built_image(base: str, repo: Path, tag: str, extra: str = "") -> Iterator[str]:
    """An image ``FROM base`` with ``repo`` at ``/testbed`` (plus the Dockerfile lines ``extra``),
    tagged ``tag`` and labelled as a test image while the block runs, removed after it."""
    import io
    import tarfile

    from workers.sandbox.docker_sandbox import docker_client

    dockerfile = f"FROM {base}\nCOPY repo /testbed\nWORKDIR /testbed\n{extra}".encode()
    context = io.BytesIO()
    with tarfile.open(fileobj=context, mode="w") as tar:
        info = tarfile.TarInfo("Dockerfile")
        info.size = len(dockerfile)
        tar.addfile(info, io.BytesIO(dockerfile))
        tar.add(str(repo), arcname="repo")
    client = docker_client()
    client.images.build(
        fileobj=io.BytesIO(context.getvalue()), custom_context=True, tag=tag, rm=True, labels={"recap-eval.test": "swe-verified"}
    )
    try:
        yield tag
    finally:
        client.images.remove(tag, force=True)
