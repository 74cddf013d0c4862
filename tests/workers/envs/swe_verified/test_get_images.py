"""``recap data images swebench-verified``: list, pull or build the missing per-instance images, through the CLI.

The Docker client is a test double (``images.list``/``images.pull``) and the harness's build
function a recording double, except in the one ``docker`` test, where the real daemon's pull
fails because no registry is reachable here.
"""

from __future__ import annotations

import json
import re
import threading
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import docker.errors
import pytest

from pipeline.cli import main
from workers.envs.swe_verified import get_images
from workers.envs.swe_verified.images import local_image, remote_image

from .conftest import write_jsonl

#: instance id, repo, version (the first four are repositories and versions the harness knows and makes
#: a test spec for without the network: django's reads its requirements file from GitHub)
INSTANCES = (
    ("pytest-dev__pytest-5103", "pytest-dev/pytest", "5.0"),
    ("pytest-dev__pytest-5221", "pytest-dev/pytest", "5.0"),
    ("sympy__sympy-20590", "sympy/sympy", "1.7"),
    ("astropy__astropy-12907", "astropy/astropy", "4.3"),
    ("fixture__offbyone-1", "fixture/offbyone", "0.1"),
)
IDS = [i for i, _, _ in INSTANCES]
NO_HOST = 'Get "https://registry-1.docker.io/v2/": dial tcp: lookup registry-1.docker.io: no such host'
DENIED = "pull access denied for swebench/sweb.eval.x86_64.fixture_1776_offbyone-1, repository does not exist"


def record(iid: str, repo: str, version: str) -> dict[str, str]:
    """A record in the dataset's schema (13 string fields)."""
    return {
        "repo": repo,
        "instance_id": iid,
        "base_commit": "0123456789abcdef0123456789abcdef01234567",
        "patch": "diff --git a/x.py b/x.py\n--- a/x.py\n+++ b/x.py\n@@ -1 +1 @@\n-a\n+b\n",
        "test_patch": "diff --git a/tests/test_x.py b/tests/test_x.py\n--- a/tests/test_x.py\n+++ b/tests/test_x.py\n"
        "@@ -1 +1 @@\n-a\n+b\n",
        "problem_statement": f"{iid} is broken",
        "hints_text": "",
        "created_at": "2024-01-01T00:00:00Z",
        "version": version,
        "FAIL_TO_PASS": json.dumps(["tests/test_x.py::test_a"]),
        "PASS_TO_PASS": json.dumps(["tests/test_x.py::test_b"]),
        "environment_setup_commit": "89abcdef0123456789abcdef0123456789abcdef",
        "difficulty": "<15 min fix",
    }


RECORDS = [record(*row) for row in INSTANCES]


@pytest.fixture
def stored(tmp_path: Path, cache: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """The five records stored as ``recap data fetch`` stores them (recap-eval's cache in tmp_path)."""
    src = write_jsonl(tmp_path / "verified.jsonl", RECORDS)
    assert main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    capsys.readouterr()
    return cache


class FakeImages:
    """``client.images``: a set of tags; ``pull`` fails for the names in ``fail`` and otherwise adds
    the image, recording each call and how many pulls ran at once (the first ``gate`` pulls wait
    for each other, so a pool of that size is seen at its full width)."""

    def __init__(self, present: set[str], fail: dict[str, Exception], gate: int = 1) -> None:
        self.present = set(present)
        self.fail = fail
        self.gate = gate
        self.pulls: list[tuple[str, str]] = []
        self.active = self.started = self.max_active = 0
        self.cond = threading.Condition()

    def list(self) -> list[SimpleNamespace]:
        return [SimpleNamespace(tags=[t]) for t in sorted(self.present)]

    def pull(self, repo: str, tag: str) -> SimpleNamespace:
        with self.cond:
            self.pulls.append((repo, tag))
            self.active += 1
            self.started += 1
            self.max_active = max(self.max_active, self.active)
            self.cond.notify_all()
            self.cond.wait_for(lambda: self.started >= self.gate, timeout=5)
        try:
            name = f"{repo}:{tag}"
            if name in self.fail:
                raise self.fail[name]
            self.present.add(name)
            return SimpleNamespace(tags=[name])
        finally:
            with self.cond:
                self.active -= 1


class FakeClient:
    def __init__(self, images: FakeImages) -> None:
        self.images = images


def use_client(monkeypatch: pytest.MonkeyPatch, images: FakeImages) -> list[int]:
    """The command gets ``FakeClient(images)``; returns the worker counts it asked a client for."""
    asked: list[int] = []
    monkeypatch.setattr(get_images, "open_client", lambda n: asked.append(n) or FakeClient(images))
    return asked


def cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, list[str], list[str]]:
    code = main(["data", "images", "swebench-verified", *argv])
    got = capsys.readouterr()
    return code, got.out.splitlines(), got.err.splitlines()


HERE = {local_image("sympy__sympy-20590")}  # built locally earlier: it counts as present


def test_list_names_the_missing_images(stored, capsys, monkeypatch) -> None:
    use_client(monkeypatch, FakeImages(HERE, {}))
    code, out, err = cli(capsys)
    assert code == 1
    assert out == [
        "swebench-verified: 5 instances selected, 1 with their image here, 4 missing",
        *(f"missing {remote_image(i)}" for i in IDS if i != "sympy__sympy-20590"),
    ]
    assert err == [
        "recap: error: data images: 4 image(s) missing; get them with `recap data images swebench-verified --pull` "
        "(Docker Hub) or `--build` (the SWE-bench harness)"
    ]
    # selectors as `recap env list` takes them: a repository, an id with and without the prefix, all once
    code, out, err = cli(capsys, "sympy/sympy", "swe-verified/pytest-dev__pytest-5103", "pytest-dev__pytest-5103")
    assert (code, err) == (1, err) and out == [
        "swebench-verified: 2 instances selected, 1 with their image here, 1 missing",
        f"missing {remote_image('pytest-dev__pytest-5103')}",
    ]
    assert cli(capsys, "sympy/sympy") == (0, ["swebench-verified: 1 instance selected, all with their image here"], [])


def test_pull_n_at_a_time_one_line_each(stored, capsys, monkeypatch) -> None:
    fail = {
        remote_image("pytest-dev__pytest-5221"): docker.errors.APIError(
            "500 Server Error: Internal Server Error", explanation=NO_HOST
        ),
        remote_image("fixture__offbyone-1"): docker.errors.ImageNotFound("404 Client Error: Not Found", explanation=DENIED),
    }
    images = FakeImages(HERE, fail, gate=2)
    asked = use_client(monkeypatch, images)
    code, out, err = cli(capsys, "--pull", "--workers", "2")
    assert code == 1
    assert out == [
        "swebench-verified: 5 instances selected, 1 with their image here, 4 missing",
        f"pulled {remote_image('pytest-dev__pytest-5103')}",
        f"failed {remote_image('pytest-dev__pytest-5221')}: {NO_HOST}",
        f"pulled {remote_image('astropy__astropy-12907')}",
        f"failed {remote_image('fixture__offbyone-1')}: {DENIED}",
        "swebench-verified: 2 pulled, 2 failed; 3 of 5 instances have their image here",
    ]
    assert err == ["recap: error: data images: 2 of 4 image(s) could not be pulled"]
    assert asked == [2]
    assert sorted(images.pulls) == sorted(tuple(remote_image(i).rsplit(":", 1)) for i in IDS if i != "sympy__sympy-20590")
    assert images.max_active == 2  # two at a time: never more, and the pool was used at its width

    # again, the registry answering now: only the two still missing are pulled, and all are here
    images.fail.clear()
    images.pulls.clear()
    code, out, err = cli(capsys, "--pull")
    assert (code, err) == (0, [])
    assert out == [
        "swebench-verified: 5 instances selected, 3 with their image here, 2 missing",
        f"pulled {remote_image('pytest-dev__pytest-5221')}",
        f"pulled {remote_image('fixture__offbyone-1')}",
        "swebench-verified: 2 pulled, 0 failed; 5 of 5 instances have their image here",
    ]
    assert images.pulls == [tuple(remote_image(i).rsplit(":", 1)) for i in ("pytest-dev__pytest-5221", "fixture__offbyone-1")]
    assert cli(capsys, "--pull") == (0, ["swebench-verified: 5 instances selected, all with their image here"], [])


def test_a_pull_that_raises_anything_is_one_line(stored, capsys, monkeypatch) -> None:
    """A timeout or a broken stream is not an API error: still one line, no traceback."""
    fail = {remote_image("pytest-dev__pytest-5103"): ConnectionError("read timed out\n  (traceback-looking text)")}
    use_client(monkeypatch, FakeImages(HERE, fail))
    code, out, err = cli(capsys, "pytest-dev__pytest-5103", "--pull")
    assert code == 1
    assert out[1] == f"failed {remote_image('pytest-dev__pytest-5103')}: read timed out"
    assert err == ["recap: error: data images: 1 of 1 image(s) could not be pulled"]


def test_dry_run_pull_and_build(stored, capsys, monkeypatch) -> None:
    images = FakeImages(HERE, {})
    use_client(monkeypatch, images)
    code, out, err = cli(capsys, "--pull", "--dry-run", "--workers", "3")
    assert (code, err) == (0, [])
    assert out == [
        "swebench-verified: 5 instances selected, 1 with their image here, 4 missing",
        *(f"would pull {remote_image(i)}" for i in IDS if i != "sympy__sympy-20590"),
        "swebench-verified: dry run: would pull 4 image(s), 3 at a time; nothing was pulled",
    ]
    assert images.pulls == []

    def never(*_a: Any, **_k: Any) -> None:
        raise AssertionError("a dry run built something")

    monkeypatch.setattr("swebench.harness.docker_build.build_instance_images", never)
    code, out, err = cli(capsys, "pytest-dev/pytest", "fixture__offbyone-1", "--build", "--dry-run")
    assert code == 1
    assert out == [
        "swebench-verified: 3 instances selected, 0 with their image here, 3 missing",
        f"would build {local_image('pytest-dev__pytest-5103')}",
        f"would build {local_image('pytest-dev__pytest-5221')}",
        f"cannot build {local_image('fixture__offbyone-1')}: the SWE-bench harness has no specification for "
        "fixture/offbyone version '0.1'",
        "swebench-verified: dry run: would build 2 image(s) with the SWE-bench harness, 4 at a time; nothing was built",
    ]
    assert err == ["recap: error: data images: 1 image(s) cannot be built by the harness"]


def test_the_harness_accepts_the_stored_records(stored) -> None:
    """The real ``make_test_spec`` on a stored record: the image it would build is the name we look for."""
    from swebench.harness.test_spec.test_spec import make_test_spec

    from workers.envs.swe_verified.dataset import records

    stored_rec = next(r for r in records() if r["instance_id"] == "pytest-dev__pytest-5103")
    spec = get_images.spec_of(make_test_spec, stored_rec)
    assert spec.instance_image_key == local_image("pytest-dev__pytest-5103")
    assert (spec.FAIL_TO_PASS, spec.PASS_TO_PASS) == (["tests/test_x.py::test_a"], ["tests/test_x.py::test_b"])


def test_build_with_the_harness(stored, capsys, monkeypatch) -> None:
    images = FakeImages(HERE, {})
    use_client(monkeypatch, images)
    calls: list[tuple[Any, list[dict[str, str]], dict[str, Any]]] = []

    def build_instance_images(client: Any, dataset: list[dict[str, str]], **kwargs: Any) -> tuple[list, list]:
        calls.append((client, dataset, kwargs))
        images.present.add(local_image("pytest-dev__pytest-5103"))
        # what the harness prints for a failed instance image (run_threadpool: the error, then a traceback)
        print("Building instance images for 3 instances")
        print(
            "<class 'swebench.harness.docker_build.BuildImageError'>: Error building image "
            f"{local_image('astropy__astropy-12907')}: The command '/bin/sh -c /root/setup_repo.sh' returned a non-zero code: 1"
        )
        print("Check (logs/build_images/instances/x/build_image.log) for more information.")
        import sys

        print("Traceback (most recent call last):\n  File ...\nBuildImageError: ...", file=sys.stderr)
        return [], []

    monkeypatch.setattr("swebench.harness.docker_build.build_instance_images", build_instance_images)
    code, out, err = cli(capsys, "--build", "--workers", "3")
    assert code == 1
    assert out == [
        "swebench-verified: 5 instances selected, 1 with their image here, 4 missing",
        f"built {local_image('pytest-dev__pytest-5103')}",
        f"failed {local_image('pytest-dev__pytest-5221')}: the harness did not build it (its log: "
        "logs/build_images/instances/sweb.eval.x86_64.pytest-dev__pytest-5221__latest/)",
        f"failed {local_image('astropy__astropy-12907')}: The command '/bin/sh -c /root/setup_repo.sh' returned a "
        "non-zero code: 1",
        f"failed {local_image('fixture__offbyone-1')}: the SWE-bench harness has no specification for fixture/offbyone "
        "version '0.1'",
        "swebench-verified: 1 built, 3 failed; 2 of 5 instances have their image here",
        "swebench-verified: the harness's build logs are under logs/build_images/",
    ]
    assert err == ["recap: error: data images: 3 of 4 image(s) could not be built"]
    [(client, dataset, kwargs)] = calls
    assert client.images is images
    by_id = {r["instance_id"]: r for r in RECORDS}
    assert dataset == [by_id[i] for i in ("pytest-dev__pytest-5103", "pytest-dev__pytest-5221", "astropy__astropy-12907")]
    assert kwargs == {"force_rebuild": False, "max_workers": 3, "namespace": None, "tag": "latest", "env_image_tag": "latest"}


def test_a_build_that_cannot_start_fails_every_instance_in_one_line(stored, capsys, monkeypatch) -> None:
    """No network: the base image cannot be built, and the harness raises out of build_instance_images."""
    use_client(monkeypatch, FakeImages(HERE, {}))

    def build_instance_images(*_a: Any, **_k: Any) -> None:
        print("Building base image (sweb.base.py.x86_64:latest)")
        raise RuntimeError(
            "Error building image sweb.base.py.x86_64:latest: failed to resolve source metadata for "
            "docker.io/library/ubuntu:22.04\nCheck (logs/build_images/base/x/build_image.log) for more information."
        )

    monkeypatch.setattr("swebench.harness.docker_build.build_instance_images", build_instance_images)
    code, out, err = cli(capsys, "pytest-dev/pytest", "--build")
    why = "Error building image sweb.base.py.x86_64:latest: failed to resolve source metadata for docker.io/library/ubuntu:22.04"
    assert code == 1
    assert out == [
        "swebench-verified: 2 instances selected, 0 with their image here, 2 missing",
        f"failed {local_image('pytest-dev__pytest-5103')}: {why}",
        f"failed {local_image('pytest-dev__pytest-5221')}: {why}",
        "swebench-verified: 0 built, 2 failed; 0 of 2 instances have their image here",
        "swebench-verified: the harness's build logs are under logs/build_images/",
    ]
    assert err == ["recap: error: data images: 2 of 2 image(s) could not be built"]


def test_a_spec_that_needs_the_network_fails_that_instance_in_one_line(tmp_path, cache, capsys, monkeypatch) -> None:
    """The harness reads django's requirements file from GitHub to make its test spec: unreachable here,
    that instance fails in one line and the others are still built."""
    import requests

    rows = [record("django__django-11099", "django/django", "3.0"), RECORDS[0]]
    assert main(["data", "fetch", "swebench-verified", "--from", str(write_jsonl(tmp_path / "v.jsonl", rows)), "--subset"]) == 0
    capsys.readouterr()

    def unreachable(url: str, **_k: Any) -> None:
        raise requests.ConnectionError(f"cannot reach {url}: no such host")

    monkeypatch.setattr("swebench.harness.test_spec.python.requests.get", unreachable)
    images = FakeImages(set(), {})
    use_client(monkeypatch, images)
    built: list[list[str]] = []

    def build_instance_images(client: Any, dataset: list[dict[str, str]], **_k: Any) -> None:
        built.append([r["instance_id"] for r in dataset])
        images.present.add(local_image("pytest-dev__pytest-5103"))

    monkeypatch.setattr("swebench.harness.docker_build.build_instance_images", build_instance_images)
    code, out, err = cli(capsys, "--build")
    assert code == 1
    assert out[1].startswith(
        f"failed {local_image('django__django-11099')}: the SWE-bench harness cannot make its test spec: cannot reach "
        "https://raw.githubusercontent.com/django/django/"
    )
    assert out[1].endswith(": no such host") and out[2] == f"built {local_image('pytest-dev__pytest-5103')}"
    assert built == [["pytest-dev__pytest-5103"]]
    assert err == ["recap: error: data images: 1 of 2 image(s) could not be built"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["django/flask"], "no SWE-bench Verified instance is 'django/flask'"),
        (["all", "nosuch__nosuch-1"], "no SWE-bench Verified instance is 'nosuch__nosuch-1'"),
        (["--pull", "--build"], "argument --build: not allowed with argument --pull"),
        (["--workers", "0"], "argument --workers: must be at least 1, got '0'"),
        (["--workers", "two"], "argument --workers: invalid whole number: 'two'"),
        (["--dry-run"], "--dry-run needs --pull or --build"),
    ],
)
def test_usage_errors_exit_2_with_one_line(argv, message, stored, capsys, monkeypatch) -> None:
    images = FakeImages(HERE, {})
    use_client(monkeypatch, images)
    code, out, err = cli(capsys, *argv)
    assert (code, out, len(err)) == (2, [], 1)
    assert err[0].startswith("recap: error: data: ") and message in err[0]
    assert images.pulls == []


def test_no_bench_and_no_data_folder(cache, capsys) -> None:
    code = main(["data", "images", "robotouille"])
    err = capsys.readouterr().err.splitlines()
    assert code == 2 and len(err) == 1 and "argument BENCH: invalid choice: 'robotouille'" in err[0]
    code = main(["data", "images", "swebench-verified"])
    err = capsys.readouterr().err.splitlines()
    assert code == 1 and len(err) == 1
    assert err[0].startswith("recap: error: data: no SWE-bench Verified data folder: run `recap data fetch swebench-verified`")


@pytest.mark.docker
def test_the_real_daemon_fails_the_pull_in_one_line(stored, capsys, docker_ready) -> None:
    """No registry is reachable here: the daemon refuses the pull, and the command says so in one line."""
    code, out, err = cli(capsys, "fixture__offbyone-1", "--pull")
    name = remote_image("fixture__offbyone-1")
    assert code == 1, (out, err)
    assert out[0] == "swebench-verified: 1 instance selected, 0 with their image here, 1 missing"
    assert re.fullmatch(rf"failed {re.escape(name)}: \S.*", out[1]), out[1]
    assert out[2:] == ["swebench-verified: 0 pulled, 1 failed; 0 of 1 instances have their image here"]
    assert err == ["recap: error: data images: 1 of 1 image(s) could not be pulled"]


def test_an_unreachable_daemon_is_one_line_exit_1(stored, capsys, monkeypatch) -> None:
    def refuse(**_k: Any) -> None:
        raise docker.errors.DockerException("Error while fetching server API version: ('Connection aborted.',\n more)")

    monkeypatch.setattr("docker.from_env", refuse)
    code, out, err = cli(capsys, "--pull")
    assert (code, out) == (1, [])
    assert err == [
        "recap: error: data: the Docker daemon is unreachable (Error while fetching server API version: ('Connection aborted.',)"
    ]
