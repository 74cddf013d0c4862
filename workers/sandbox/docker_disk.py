"""Every writable place of a docker sandbox bounded (issue 35 item 3).

Watching only the repository folder let a command fill ``/tmp`` of a container with a 20 MB limit
with 218 MB (``/var/lib/docker`` grew 456 MB). Two ways to bound all of it, chosen per daemon:

* **a quota on the container's writable layer** (``--storage-opt size=``), where the storage
  driver has one (overlay2 on xfs mounted with ``pquota``, devicemapper, btrfs, zfs): everything a
  command writes anywhere is under one bound, ``limits.disk_bytes`` plus the scratch folders'
  :attr:`~workers.sandbox.base.SandboxLimits.scratch_bytes` each. Asked of the daemon once
  (:func:`storage_quota_supported`: a container is created with the option, never started);
* **otherwise** (overlay2 on ext4, this project's hosts): a **read-only root filesystem**, with the
  places a program writes to as size-limited tmpfs mounts (:func:`tmpfs_mounts`): ``/tmp``,
  ``/var/tmp``, ``$HOME`` and ``/run`` at ``scratch_bytes`` each, and the repository folder itself
  at ``disk_bytes``, so it stays at its path (the SWE-bench harness's editable installs point at
  ``/testbed``). A tmpfs mount cannot receive the daemon's ``put_archive`` (moby#22020) nor a
  volume's copy-up from the image (a tmpfs-backed local volume is mounted empty), so the
  repository is streamed in as a tar on an exec's stdin (:func:`populate`): from the host's clone,
  or, for an image that holds the repository, from a created (never started) container of the
  same image, chunk by chunk, never whole in the worker.

The cost of the tmpfs way: the repository and the scratch folders live in memory, charged to the
container's memory limit (``memory_bytes``); a write past a mount's size fails with "No space
left on device". The wrapper's ``du`` of the repository after each command stays (the size the
model is told), and ``ulimit -f`` still caps a single file.
"""

from __future__ import annotations

import posixpath
import socket
import threading
import time
from collections.abc import Iterable, Mapping
from typing import Any

from workers.sandbox.base import SandboxError, SandboxLimits

#: the scratch folders every program may write to (``$HOME`` is added by :func:`tmpfs_mounts`)
SCRATCH = ("/tmp", "/var/tmp", "/run")

_QUOTA: dict[str, bool] = {}
_QUOTA_LOCK = threading.Lock()


def storage_quota_supported(client: Any, image: str) -> bool:
    """Whether the daemon's storage driver takes ``--storage-opt size=`` (asked once per daemon:
    a container of ``image`` is created with it, and removed, never started)."""
    key = str(client.info().get("ID", "")) if hasattr(client, "info") else ""
    with _QUOTA_LOCK:
        if key in _QUOTA:
            return _QUOTA[key]
        import docker.errors

        try:
            c = client.containers.create(image, ["true"], storage_opt={"size": "64M"}, labels={"recap-eval.probe": "1"})
        except docker.errors.APIError:
            ok = False
        else:
            ok = True
            try:
                c.remove(force=True)
            except docker.errors.DockerException:
                pass
        _QUOTA[key] = ok
        return ok


def tmpfs_mounts(limits: SandboxLimits, workdir: str, home: str) -> dict[str, str]:
    """The size-limited tmpfs mounts of a read-only container: the scratch folders, ``home`` and
    the repository folder ``workdir`` (programs run from all of them: ``exec``)."""
    mounts = {p: f"rw,exec,nosuid,nodev,size={limits.scratch_bytes}" for p in (*SCRATCH, home)}
    mounts[workdir] = f"rw,exec,nosuid,nodev,size={limits.disk_bytes},mode=755"
    return mounts


def quota_size(limits: SandboxLimits) -> str:
    """The writable layer's quota: the repository's limit plus each scratch folder's."""
    return str(limits.disk_bytes + 4 * limits.scratch_bytes)


def populate(client: Any, container: Any, workdir: str, chunks: Iterable[bytes]) -> None:
    """Extract the tar stream ``chunks`` (members named ``<basename of workdir>/...``) into
    ``workdir``'s parent in ``container``, through an exec's stdin; SandboxError when tar fails
    (the repository does not fit its mount, say)."""
    parent = posixpath.dirname(workdir.rstrip("/")) or "/"
    argv = ["tar", "-x", "-p", "-C", parent, "-f", "-"]
    api = client.api
    exec_id = api.exec_create(container.id, argv, stdin=True, stdout=True, stderr=True)["Id"]
    sock = api.exec_start(exec_id, socket=True)
    raw = getattr(sock, "_sock", sock)
    out = bytearray()
    reader = threading.Thread(target=_drain, args=(raw, out), daemon=True)
    reader.start()
    try:
        for chunk in chunks:
            raw.sendall(chunk)
        raw.shutdown(socket.SHUT_WR)
    except OSError:
        pass  # tar stopped reading (it failed): its exit status says why
    reader.join(timeout=600)
    sock.close()
    code = _exit_code(api, exec_id)
    if code != 0:
        said = bytes(out[-300:]).decode("utf-8", errors="replace").strip()
        raise SandboxError(f"copying the repository into {workdir} failed (tar exit {code}): {said}")


def image_tree(client: Any, image: str, path: str, labels: Mapping[str, str]) -> tuple[Any, Iterable[bytes]]:
    """A created (never started) container of ``image`` and the tar stream of its ``path``; the
    caller removes the container when the stream is read."""
    import docker.errors

    helper = client.containers.create(image, ["true"], labels=dict(labels), network_disabled=True)
    try:
        stream, _stat = helper.get_archive(path, chunk_size=1 << 20)
    except docker.errors.NotFound:
        helper.remove(force=True)
        raise SandboxError(f"the image {image} has no {path}") from None
    return helper, stream


def _drain(raw: Any, out: bytearray) -> None:
    """Read the exec's multiplexed output until it ends (keep its last bytes, for the error)."""
    while True:
        try:
            chunk = raw.recv(1 << 16)
        except OSError:
            return
        if not chunk:
            return
        out += chunk
        del out[:-4096]


def _exit_code(api: Any, exec_id: str) -> int:
    for _ in range(500):
        info = api.exec_inspect(exec_id)
        if not info.get("Running"):
            code = info.get("ExitCode")
            return int(code) if code is not None else -1
        time.sleep(0.02)
    return -1
