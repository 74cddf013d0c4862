"""The harness's image names, and a sweep whose instances lack their image refused before anything runs."""

from __future__ import annotations

import pytest

from workers.envs.swe_verified import images

from .conftest import write_jsonl


@pytest.mark.parametrize(
    "instance_id, remote, local",
    [
        (
            "django__django-11099",
            "swebench/sweb.eval.x86_64.django_1776_django-11099:latest",
            "sweb.eval.x86_64.django__django-11099:latest",
        ),
        (
            "sphinx-doc__sphinx-8721",
            "swebench/sweb.eval.x86_64.sphinx-doc_1776_sphinx-8721:latest",
            "sweb.eval.x86_64.sphinx-doc__sphinx-8721:latest",
        ),
        (
            "pytest-dev__pytest-5103",
            "swebench/sweb.eval.x86_64.pytest-dev_1776_pytest-5103:latest",
            "sweb.eval.x86_64.pytest-dev__pytest-5103:latest",
        ),
        (
            "PyCQA__pylint-4661",  # upper case: lower-cased, as the harness does
            "swebench/sweb.eval.x86_64.pycqa_1776_pylint-4661:latest",
            "sweb.eval.x86_64.pycqa__pylint-4661:latest",
        ),
    ],
)
def test_image_names_follow_the_harness(instance_id: str, remote: str, local: str) -> None:
    assert images.image_names(instance_id) == (remote, local)
    try:
        from swebench.harness.test_spec.test_spec import TestSpec
    except ImportError:
        return  # the rule above is the harness's (swebench 4.x test_spec.py); checked against it where installed
    spec = TestSpec(
        instance_id=instance_id,
        repo="r",
        version="v",
        repo_script_list=[],
        eval_script_list=[],
        env_script_list=[],
        arch="x86_64",
        FAIL_TO_PASS=[],
        PASS_TO_PASS=[],
        language="py",
        docker_specs={},
        namespace="swebench",
    )
    assert spec.instance_image_key == remote
    assert TestSpec(**{**spec.__dict__, "namespace": None}).instance_image_key == local


SWEEP = """run: verified
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
environments:
  - benchmark: swe-verified
    tasks: [all]
"""


def test_sweep_with_missing_images_is_refused_in_preflight(tmp_path, records, cache, capsys, monkeypatch) -> None:
    import pipeline.cli as cli
    import pipeline.cli.run as run_command

    src = write_jsonl(tmp_path / "verified.jsonl", records)
    assert cli.main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    capsys.readouterr()
    listings = []
    present = {images.local_image("fixture__offbyone-1")}
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: listings.append(1) or present)

    def never(*_a, **_k):
        raise AssertionError("the run started: the preflight did not stop it")

    monkeypatch.setattr(run_command, "_execute", never)
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=out))
    code = cli.main(["run", str(spec), "--progress", "off"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2
    assert err == [
        "recap: error: sweep.yaml: environments[0] (swe-verified): 2 of 3 instances have no image here (first: "
        "swebench/sweb.eval.x86_64.fixture_1776_format-1:latest); pull them (docker pull "
        "swebench/sweb.eval.x86_64.<id>:latest) or build them with the SWE-bench harness (python -m "
        "swebench.harness.prepare_images)"
    ]
    assert listings == [1]  # one listing for every instance
    assert not out.exists()


def test_local_sandbox_is_refused(tmp_path, records, cache, capsys, monkeypatch) -> None:
    import pipeline.cli as cli

    src = write_jsonl(tmp_path / "verified.jsonl", records)
    assert cli.main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    capsys.readouterr()
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=tmp_path / "out") + "    options:\n      sandbox: local\n")
    assert cli.main(["run", str(spec), "--progress", "off"]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "recap: error: sweep.yaml: environments[0] (swe-verified): swe-verified runs in the SWE-bench harness's "
        "per-instance Docker images (the repository and its environment are in the image): sandbox 'local' cannot "
        "run it; use sandbox: docker"
    ]
