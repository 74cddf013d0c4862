"""Remove what sandboxes left behind: the driver calls this for a killed worker and on resume.

A worker killed mid-episode never reaches ``Sandbox.close``; everything it started carries the
sandbox labels (:data:`workers.sandbox.base.LABEL_RUN` and the others), so the driver removes by
label: every container carrying them, and every local sandbox registered with them
(:mod:`workers.sandbox.registry`: its running process group, its pids cgroup, its temporary root
and the tmpfs mounted there).
"""

from __future__ import annotations

import logging
import os
import signal
from collections.abc import Mapping

from workers.sandbox import registry
from workers.sandbox.local_sandbox import kill_cgroup, remove_root

log = logging.getLogger(__name__)


def remove_labelled(labels: Mapping[str, str], *, docker: bool = True) -> int:
    """Remove every container and local sandbox carrying all of ``labels``; the number removed.
    Empty ``labels`` are refused (they would match everything). Without a reachable Docker daemon
    only local sandboxes are removed (no daemon: no container of ours can be running)."""
    if not labels:
        raise ValueError("remove_labelled needs at least one label (an empty set matches everything)")
    return (_remove_containers(labels) if docker else 0) + _remove_local(labels)


def _remove_containers(labels: Mapping[str, str]) -> int:
    import docker as docker_sdk
    import docker.errors

    try:
        client = docker_sdk.from_env()
        found = client.containers.list(all=True, filters={"label": [f"{k}={v}" for k, v in labels.items()]})
    except docker.errors.DockerException:
        return 0
    n = 0
    for c in found:
        try:
            c.remove(force=True)
            n += 1
        except docker.errors.NotFound:
            pass  # removed meanwhile (its episode closed it)
        except docker.errors.APIError as exc:
            # 409 "removal already in progress": its own close is removing it; anything else must
            # not keep the other containers from going
            if exc.status_code != 409:
                log.warning("could not remove container %s: %s", c.short_id, str(exc).splitlines()[0][:200])
    return n


def _remove_local(labels: Mapping[str, str]) -> int:
    n = 0
    for sandbox_id, entry in registry.entries():
        if not registry.matches(entry.get("labels") or {}, labels):
            continue
        pgid = entry.get("pgid")
        if isinstance(pgid, int) and pgid > 1:
            try:
                os.killpg(pgid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
        kill_cgroup(entry.get("cgroup"))
        root = entry.get("root")
        if isinstance(root, str) and os.path.basename(root).startswith("recap-sandbox-local-"):
            remove_root(root)  # its tmpfs unmounted first, when it is one
        registry.remove_entry(sandbox_id)
        n += 1
    return n
