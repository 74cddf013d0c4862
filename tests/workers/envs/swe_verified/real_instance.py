"""A real SWE-bench Verified instance's image, built offline the way the harness lays its images out.

The record (``sympy__sympy-23262.json``) and a git repository holding its base commit are shared
test data, read from ``../shared/data/swebench-verified-repos/`` beside the checkout (or
``$RECAP_SWE_REAL_RECORD`` / ``$RECAP_SWE_REAL_REPO``): the record carries SymPy's own patches and
the repository is SymPy's code, both fetched from public repositories, so neither is committed
here (their provenance and how to make them: ``real_instance.md`` beside this file). The image is what the harness's own scripts make of it - ``make_test_spec(record)``
of the installed ``swebench`` package - with only what needs the network swapped:

* the repository: the harness's ``install_repo_script`` runs unchanged (its ``git clone -o origin
  --single-branch``, ``git reset --hard <base>``, remote and tag removal, ``git gc``, the check
  that no later commit is left, ``conda activate testbed``, the repository's install
  ``python -m pip install -e .`` and the ``git commit --allow-empty -am SWE-bench`` on top), except
  that it clones a local shallow copy of the repository at the base commit (``file://``) instead
  of ``https://github.com/<repo>``. That copy comes from a git repository holding the base commit
  (:func:`repository_source`): none is committed here (see the README).
* the environment: the harness's ``setup_env_script`` makes a conda environment ``testbed``
  (``python=3.9 mpmath flake8``, then ``pip install mpmath==1.3.0 flake8-comprehensions``); here it
  is a pip environment at the same place, ``/opt/miniconda3/envs/testbed``, on the sandbox image's
  Python 3.11, holding ``mpmath==1.3.0`` from PyPI (the linters are left out: no test imports
  them), with ``PIP_NO_INDEX``/``PIP_FIND_LINKS`` pointing pip at the wheels inside the image so
  the install in the harness's scripts (setup and eval) runs without a network.
  ``/opt/miniconda3/bin/activate`` defines a ``conda`` whose ``conda activate NAME`` activates that
  environment, so the harness's ``source /opt/miniconda3/bin/activate && conda activate testbed``
  lines run as they are.

The image is tagged by a hash of everything that goes into it, so it is built once per machine
(about a minute) and reused; a test tags it under the harness's published name for the instance
while it runs.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[4]
#: the shared test data's folder (beside the checkout, as the other shared test data)
SHARED = ROOT.parent / "shared" / "data" / "swebench-verified-repos"
#: the record, unless ``RECAP_SWE_REAL_RECORD`` names another file
DEFAULT_RECORD = SHARED / "sympy__sympy-23262.json"
RECORD_ENV = "RECAP_SWE_REAL_RECORD"
#: where a git repository holding the record's base commit is looked for when
#: ``RECAP_SWE_REAL_REPO`` does not name one
DEFAULT_SOURCE = SHARED / "sympy"
SOURCE_ENV = "RECAP_SWE_REAL_REPO"
#: the pip environment's wheels, pinned (pip and the build back end for ``pip install -e .``,
#: and the harness's ``pip_packages`` pin for sympy 1.11: ``mpmath==1.3.0``)
WHEELS = ("pip==24.0", "setuptools==69.5.1", "wheel==0.43.0", "mpmath==1.3.0")
IMAGE_REPO = "recap-eval-test/swe-real"
ENV_DIR = "/opt/miniconda3/envs/testbed"
SOURCE_IN_IMAGE = "/tmp/upstream.git"

#: stands in for miniconda's activate script: ``conda activate NAME`` activates the pip
#: environment of that name (and sets what conda sets, which the harness's script echoes)
ACTIVATE = """# recap-eval test image: conda stand-in (the image has a pip environment, not conda)
conda() {
  if [ "$1" = activate ]; then
    . "/opt/miniconda3/envs/$2/bin/activate"
    export CONDA_DEFAULT_ENV="$2" CONDA_PREFIX="/opt/miniconda3/envs/$2"
  fi
}
"""


def record_file() -> Path:
    """Where the record is read from (``$RECAP_SWE_REAL_RECORD``, else :data:`DEFAULT_RECORD`)."""
    named = os.environ.get(RECORD_ENV)
    return Path(named) if named else DEFAULT_RECORD


def load_record() -> dict[str, str] | None:
    """The shared record (the dataset's 13 fields), or None where it is absent."""
    path = record_file()
    if not path.is_file():
        return None
    record: dict[str, str] = json.loads(path.read_text(encoding="utf-8"))
    return record


def repository_source(base_commit: str) -> Path | None:
    """A git repository here that holds ``base_commit`` (``$RECAP_SWE_REAL_REPO``, else
    :data:`DEFAULT_SOURCE`), or None."""
    named = os.environ.get(SOURCE_ENV)
    path = Path(named) if named else DEFAULT_SOURCE
    if not path.exists():
        return None
    done = subprocess.run(["git", "-C", str(path), "cat-file", "-e", f"{base_commit}^{{commit}}"], capture_output=True)
    return path if done.returncode == 0 else None


def wheels(cache: Path) -> list[Path]:
    """:data:`WHEELS` in ``cache`` (downloaded from PyPI the first time)."""
    cache.mkdir(parents=True, exist_ok=True)
    names = [w.split("==") for w in WHEELS]
    found = [next(iter(sorted(cache.glob(f"{n}-{v}-*.whl"))), None) for n, v in names]
    if any(f is None for f in found):
        cmd = [sys.executable, "-m", "pip", "download", "-q", "--only-binary=:all:", "--no-deps", "-d", str(cache), *WHEELS]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            tail = (done.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"downloading {', '.join(WHEELS)} from PyPI into {cache} failed: {tail}")
        found = [next(iter(sorted(cache.glob(f"{n}-{v}-*.whl"))), None) for n, v in names]
    return [f for f in found if f is not None]


def shallow_copy(source: Path, base_commit: str, dest: Path) -> Path:
    """A bare repository at ``dest`` holding only ``base_commit`` (depth 1) on its default branch."""
    subprocess.run(["git", "init", "-q", "--bare", "-b", "main", str(dest)], check=True)
    subprocess.run(["git", "-C", str(dest), "fetch", "-q", "--depth", "1", f"file://{source.resolve()}", base_commit], check=True)
    subprocess.run(["git", "-C", str(dest), "update-ref", "refs/heads/main", base_commit], check=True)
    return dest


def harness_scripts(record: dict[str, str]) -> tuple[str, str]:
    """The harness's repository setup script for ``record`` (cloning the copy inside the image) and
    its eval script, both from ``make_test_spec``."""
    from swebench.harness.test_spec.test_spec import make_test_spec

    spec = make_test_spec(record)
    url = f"https://github.com/{record['repo']}"
    assert spec.install_repo_script.count(url) == 1, spec.install_repo_script
    return spec.install_repo_script.replace(url, f"file://{SOURCE_IN_IMAGE}"), spec.eval_script


def dockerfile(base: str, wheel_names: list[str]) -> str:
    """The build: the pip environment from the wheels (pip runs from its own wheel), the conda
    stand-in, the repository copy, then the harness's setup script."""
    pip = next(w for w in wheel_names if w.startswith("pip-"))
    return (
        f"FROM {base}\n"
        "COPY wheels /opt/wheels\n"
        "COPY activate /opt/miniconda3/bin/activate\n"
        "ENV PIP_NO_INDEX=1 PIP_FIND_LINKS=/opt/wheels PIP_DISABLE_PIP_VERSION_CHECK=1\n"
        f"RUN python3 -m venv --without-pip {ENV_DIR} && {ENV_DIR}/bin/python /opt/wheels/{pip}/pip install -q "
        f"{' '.join(WHEELS)}\n"
        f"COPY upstream.git {SOURCE_IN_IMAGE}\n"
        "COPY setup_repo.sh /root/setup_repo.sh\n"
        f"RUN bash /root/setup_repo.sh && rm -rf {SOURCE_IN_IMAGE}\n"
        "WORKDIR /testbed\n"
    )


def image_tag(base_id: str, parts: dict[str, bytes]) -> str:
    """``IMAGE_REPO:<hash>`` of the base image and every file of the build context."""
    h = hashlib.sha256(base_id.encode())
    for name in sorted(parts):
        h.update(name.encode() + b"\0" + hashlib.sha256(parts[name]).digest())
    return f"{IMAGE_REPO}:{h.hexdigest()[:16]}"


def build(base: str, source: Path, work: Path, wheel_cache: Path) -> tuple[str, float]:
    """The instance's image (its content-hash tag) and the seconds its build took (0 when it existed)."""
    import time

    import docker.errors

    from workers.sandbox.docker_sandbox import docker_client

    record = load_record()
    if record is None:
        raise FileNotFoundError(f"the record {record_file()} is absent (real_instance.md)")
    client = docker_client(1800)
    base_id = client.images.get(base).id
    setup, _ = harness_scripts(record)
    whl = wheels(wheel_cache)
    upstream = shallow_copy(source, record["base_commit"], work / "upstream.git")
    files = {
        "Dockerfile": dockerfile(base, [w.name for w in whl]).encode(),
        "activate": ACTIVATE.encode(),
        "setup_repo.sh": setup.encode(),
        **{f"wheels/{w.name}": w.read_bytes() for w in whl},
    }
    # the copy's content is the base commit itself: its hash stands for it
    tag = image_tag(base_id, {**files, "upstream.git": record["base_commit"].encode()})
    try:
        client.images.get(tag)
        return tag, 0.0
    except docker.errors.ImageNotFound:
        pass
    context = io.BytesIO()
    with tarfile.open(fileobj=context, mode="w") as tar:
        for name, data in files.items():
            info = tarfile.TarInfo(name)
            info.size, info.mode = len(data), 0o755 if name.endswith(".sh") else 0o644
            tar.addfile(info, io.BytesIO(data))
        tar.add(str(upstream), arcname="upstream.git")
    started = time.monotonic()
    try:
        client.images.build(
            fileobj=io.BytesIO(context.getvalue()),
            custom_context=True,
            tag=tag,
            rm=True,
            forcerm=True,
            labels={"recap-eval.test": "swe-verified-real"},
        )
    except docker.errors.BuildError as exc:
        tail = "".join(str(c.get("stream", c.get("error", ""))) for c in list(exc.build_log)[-30:])
        raise RuntimeError(f"building {tag} failed: {exc}\n{tail}") from None
    finally:
        shutil.rmtree(upstream, ignore_errors=True)
    return tag, time.monotonic() - started
