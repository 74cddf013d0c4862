"""What only the docker sandbox promises (isolation, labels, removal), open_sandbox's refusals,
and remove_labelled for a killed owner (both kinds)."""

from __future__ import annotations

import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.workers.sandbox.conftest import Repo
from workers.sandbox import (
    LABEL_RUN,
    LABEL_WORKER,
    Sandbox,
    SandboxError,
    SandboxLimits,
    SandboxSpec,
    open_sandbox,
    remove_labelled,
)
from workers.sandbox.wrapper import parse

docker = pytest.mark.docker


def _containers(labels: dict[str, str]) -> list[object]:
    import docker as sdk

    return sdk.from_env().containers.list(all=True, filters={"label": [f"{k}={v}" for k, v in labels.items()]})


@pytest.fixture
def dsb(docker_ready: str, repo: Repo, labels: dict[str, str]) -> Iterator[Sandbox]:
    sb = open_sandbox("docker", SandboxSpec(str(repo.path), repo.commit, labels=labels))
    yield sb
    sb.close()


@docker
def test_container_is_labelled_without_network_and_limited(dsb: Sandbox, labels: dict[str, str]) -> None:
    (c,) = _containers(labels)
    attrs = c.attrs  # type: ignore[attr-defined]
    import docker as sdk

    image_labels = sdk.from_env().images.get(attrs["Config"]["Image"]).labels or {}
    assert attrs["Config"]["Labels"] == {**image_labels, **labels}  # ours on top of what the image carries (its recipe)
    hc = attrs["HostConfig"]
    lim = SandboxLimits()
    assert (hc["NetworkMode"], hc["Memory"], hc["PidsLimit"]) == ("none", lim.memory_bytes, lim.pids)
    names = {e.split("=", 1)[0] for e in attrs["Config"]["Env"]}
    assert names == {"PATH", "HOME", "LANG"}


@docker
def test_rm_rf_root_leaves_the_host_untouched(dsb: Sandbox, repo: Repo, tmp_path: Path) -> None:
    marker = tmp_path / "host-marker.txt"
    marker.write_text("still here\n")
    try:
        dsb.run("rm -rf --no-preserve-root / 2>/dev/null; true", timeout_s=60)
    except SandboxError:
        pass  # the sandbox may be broken afterwards; the host must not be
    assert marker.read_text() == "still here\n"
    assert (repo.path / "a.txt").read_text() == "uncommitted\n"
    assert Path("/bin/bash").exists() and Path("/etc/passwd").exists()


@docker
def test_writes_outside_the_repository_stay_in_the_container(dsb: Sandbox) -> None:
    name = f"/tmp/recap-sandbox-escape-{uuid.uuid4().hex}"
    r = dsb.run(f"echo x > {name} && cat {name}")
    assert (r.exit_code, r.output) == (0, "x\n")
    assert not Path(name).exists()


@docker
def test_close_removes_the_container(docker_ready: str, repo: Repo, labels: dict[str, str]) -> None:
    sb = open_sandbox("docker", SandboxSpec(str(repo.path), repo.commit, labels=labels))
    assert len(_containers(labels)) == 1
    sb.close()
    assert _containers(labels) == []
    sb.close()


@pytest.mark.parametrize("kind", [pytest.param("docker", marks=docker), "local"])
def test_remove_labelled_cleans_up_after_a_killed_owner(
    request: pytest.FixtureRequest, kind: str, repo: Repo, labels: dict[str, str]
) -> None:
    if kind == "docker":
        request.getfixturevalue("docker_ready")
    mine = {**labels, LABEL_WORKER: "w1"}
    other = {**labels, LABEL_WORKER: "w2"}
    left = open_sandbox(kind, SandboxSpec(str(repo.path), repo.commit, labels=mine))  # type: ignore[arg-type]
    kept = open_sandbox(kind, SandboxSpec(str(repo.path), repo.commit, labels=other))  # type: ignore[arg-type]
    try:
        # the owner is "killed": it never calls close()
        assert remove_labelled({LABEL_WORKER: "w1", LABEL_RUN: labels[LABEL_RUN]}) == 1
        if kind == "docker":
            assert _containers(mine) == [] and len(_containers(other)) == 1
        else:
            assert not Path(left.root).exists() and Path(kept.root).exists()  # type: ignore[attr-defined]
        assert kept.run("echo ok").output == "ok\n"
        assert remove_labelled({LABEL_WORKER: "w1", LABEL_RUN: labels[LABEL_RUN]}) == 0
    finally:
        kept.close()


def test_remove_labelled_refuses_empty_labels() -> None:
    with pytest.raises(ValueError, match="needs at least one label"):
        remove_labelled({})


def test_open_sandbox_refusals(repo: Repo, tmp_path: Path) -> None:
    """What would fail the same way on every try is not the container service (``service`` False)."""
    with pytest.raises(SandboxError, match=r"^unknown sandbox kind 'vm' \(known: docker, local\)$") as e1:
        open_sandbox("vm", SandboxSpec(str(repo.path), repo.commit))
    with pytest.raises(SandboxError, match=f"^repo_path is not a git repository: {tmp_path}$") as e2:
        open_sandbox("local", SandboxSpec(str(tmp_path), "HEAD"))
    with pytest.raises(SandboxError, match=f"^base_commit 'deadbeef' is not a commit of {repo.path}$") as e3:
        open_sandbox("local", SandboxSpec(str(repo.path), "deadbeef"))
    assert (e1.value.service, e2.value.service, e3.value.service) == (False, False, False)


def test_open_sandbox_says_how_to_start_an_unreachable_daemon(repo: Repo, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("DOCKER_HOST", "unix:///nonexistent/docker.sock")
    with pytest.raises(
        SandboxError, match=r"^the Docker daemon is unreachable \(.*\); start it .*or use `sandbox: local`$"
    ) as err:
        open_sandbox("docker", SandboxSpec(str(repo.path), repo.commit))
    assert err.value.service  # the service: infrastructure, which the next resume tries again


@docker
def test_a_removed_container_is_the_service_failing_for_commands_and_files(
    docker_ready: str, repo: Repo, labels: dict[str, str]
) -> None:
    """A container removed under a live sandbox (a daemon restart, an OOM kill of the container)
    answers every command and file access with the service's SandboxError - never a "no such
    file" the agent would be shown as if its path were wrong."""
    box = open_sandbox("docker", SandboxSpec(str(repo.path), repo.commit, labels=labels))
    try:
        assert box.read_file("a.txt")
        (c,) = _containers(labels)
        c.remove(force=True)  # type: ignore[attr-defined]
        for act in (lambda: box.run("true"), lambda: box.read_file("a.txt"), lambda: box.write_file("x.txt", b"x")):
            with pytest.raises(SandboxError, match="^the sandbox container is gone$") as err:
                act()
            assert err.value.service
    finally:
        box.close()  # removing a container that is gone is no error
    assert _containers(labels) == []


@docker
def test_open_sandbox_names_the_build_command_for_a_missing_image(docker_ready: str, repo: Repo) -> None:
    tag = f"recap-eval/no-such-image:{uuid.uuid4().hex[:8]}"
    with pytest.raises(
        SandboxError, match=f"^the sandbox image {tag} is missing; build it with `bash scripts/build_sandbox_image.sh`$"
    ):
        open_sandbox("docker", SandboxSpec(str(repo.path), repo.commit, image=tag))


def test_wrapper_trailer_cannot_be_forged_by_output() -> None:
    raw = b"out\nabc 0 1 2 0\nmore\nnonce1 7 22 300 1\n"
    res = parse(raw, "nonce1")
    assert res is not None
    assert (res.output, res.rc, res.output_bytes, res.repo_bytes, res.disk_killed) == (
        b"out\nabc 0 1 2 0\nmore",
        7,
        22,
        300,
        True,
    )
    assert parse(b"out\nabc 0 1 2 0\n", "nonce1") is None


class _DaemonFailsMidStream:
    """A container whose file read breaks off mid-stream (the daemon failing while it sends the
    exec's output: the file operations run in the container, workers.sandbox.docker_files)."""

    status = "running"
    id = "c0ffee"

    def reload(self) -> None:
        pass

    def exec_run(self, cmd: list[str], **kw: object) -> tuple[int, bytes]:
        import requests

        raise requests.exceptions.ChunkedEncodingError("Connection broken: IncompleteRead")


def test_a_daemon_failing_mid_stream_is_the_service_not_a_missing_file() -> None:
    from workers.sandbox.docker_sandbox import DockerSandbox

    box = object.__new__(DockerSandbox)  # no daemon here: the container double is all it talks to
    box._closed, box._container, box.workdir = False, _DaemonFailsMidStream(), "/repo"
    with pytest.raises(SandboxError, match=r"^the sandbox cannot run commands: Connection broken: IncompleteRead$") as err:
        box.read_file("a.txt")
    assert err.value.service
