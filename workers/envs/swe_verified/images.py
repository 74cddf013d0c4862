"""Each SWE-bench Verified instance runs in the harness's own per-instance image; which ones are here.

The harness names an instance's image (swebench 4.x, ``swebench/harness/test_spec/test_spec.py``
``TestSpec.instance_image_key``) ``sweb.eval.x86_64.<instance_id lower-cased>:latest`` when it
builds it locally, and ``<namespace>/`` + that name with every ``__`` written ``_1776_`` when it
pulls it (Docker Hub refuses ``__``; the published namespace is ``swebench``). An instance has
its image here when either name is in the local image list. The image holds the repository at
``/testbed`` at the base commit, with the instance's environment installed (conda env ``testbed``).

:func:`local_images` is one ``docker images`` listing (one API call), so checking 500 instances
takes as long as checking one.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Any

from workers.sandbox.base import SandboxError

#: the namespace the harness publishes its images under on Docker Hub
NAMESPACE = "swebench"
ARCH = "x86_64"
TAG = "latest"
#: where the repository sits inside the image, and the conda environment the harness activates
TESTBED = "/testbed"
CONDA_ENV_BIN = "/opt/miniconda3/envs/testbed/bin"
CONDA_BIN = "/opt/miniconda3/bin"


def remote_image(instance_id: str, namespace: str = NAMESPACE) -> str:
    """The published name: ``swebench/sweb.eval.x86_64.django_1776_django-11099:latest``."""
    return f"{namespace}/sweb.eval.{ARCH}.{instance_id.lower()}:{TAG}".replace("__", "_1776_")


def local_image(instance_id: str) -> str:
    """The name the harness gives an image it builds without a namespace: ``sweb.eval.x86_64.django__django-11099:latest``."""
    return f"sweb.eval.{ARCH}.{instance_id.lower()}:{TAG}"


def image_names(instance_id: str) -> tuple[str, str]:
    """The names an instance's image may have here, the published one first."""
    return remote_image(instance_id), local_image(instance_id)


def local_images() -> set[str]:
    """Every ``repository:tag`` of the local daemon, in one listing; SandboxError (one line) when
    the daemon is unreachable."""
    import docker.errors

    from workers.sandbox.docker_sandbox import docker_client

    client = docker_client(30.0)
    try:
        listed = client.api.images()
    except docker.errors.DockerException as exc:
        raise SandboxError(f"cannot list the Docker images: {str(exc).splitlines()[0][:160]}", service=True) from None
    return {tag for image in listed for tag in (image.get("RepoTags") or []) if tag and tag != "<none>:<none>"}


def image_of(instance_id: str, present: set[str]) -> str | None:
    """The instance's image among ``present`` (either name), or None."""
    return next((name for name in image_names(instance_id) if name in present), None)


def missing_images(instance_ids: Iterable[str], present: set[str]) -> list[str]:
    """The published image names of the instances that have no image among ``present``, in order."""
    return [remote_image(i) for i in instance_ids if image_of(i, present) is None]


def how_to_get(missing: Sequence[str]) -> str:
    """How to get missing images: pull where Docker Hub is reachable, or build with the harness."""
    return (
        f"`docker pull {missing[0]}` (and the others) where Docker Hub is reachable, or build them with the "
        "SWE-bench harness (python -m swebench.harness.prepare_images --dataset_name princeton-nlp/SWE-bench_Verified "
        "--instance_ids ...)"
    )


def images_line(instance_ids: Sequence[str], present: set[str], shown: int = 3) -> str:
    """``recap data check``'s line: how many instances have their image, the first missing ones and the count."""
    missing = missing_images(instance_ids, present)
    head = f"images: {len(instance_ids) - len(missing)} of {len(instance_ids)} instances have their image locally"
    if not missing:
        return head
    more = f" and {len(missing) - shown} more" if len(missing) > shown else ""
    return f"{head}; {len(missing)} missing: {', '.join(missing[:shown])}{more}; get them with {how_to_get(missing)}"


def present_tags(client: Any) -> set[str]:
    """Every ``repository:tag`` the daemon of ``client`` (a Docker SDK client) holds, from one
    ``images.list()``; SandboxError (one line) when it cannot list them."""
    import docker.errors

    try:
        listed = client.images.list()
    except docker.errors.DockerException as exc:
        raise SandboxError(f"cannot list the Docker images: {str(exc).splitlines()[0][:160]}", service=True) from None
    return {tag for image in listed for tag in (image.tags or [])}
