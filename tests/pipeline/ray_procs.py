"""The processes of the local Ray cluster a test runs on, read from /proc: what the cluster tests
check (the GCS's settings, the raylet's agents) is what Ray really started, not our arguments."""

from __future__ import annotations

import base64
import json
import os
from typing import Any

import pytest


def children(pid: int) -> list[list[str]]:
    """The command lines of ``pid``'s child processes."""
    found = []
    for entry in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{entry}/stat") as fh:
                ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            if ppid != pid:
                continue
            with open(f"/proc/{entry}/cmdline", "rb") as fh:
                found.append(fh.read().decode(errors="replace").split("\0"))
        except (OSError, IndexError, ValueError):
            continue
    return found


def session_cluster() -> tuple[str, int]:
    """(session folder, raylet pid) of the cluster this process started with ``init_ray``; the test
    is skipped where Ray was started some other way."""
    import ray

    from pipeline import raysetup

    if raysetup._owned is None:
        pytest.skip("Ray was started outside init_ray in this process")
    node = ray._private.worker._global_node
    assert node is not None
    raylet = node.all_processes[ray._private.ray_constants.PROCESS_TYPE_RAYLET][0].process.pid
    return node.get_session_dir_path(), raylet


def gcs_config(session_dir: str) -> dict[str, Any]:
    """The settings the cluster's GCS was started with (its ``--config_list``, base64 JSON; the
    raylet and the workers take theirs from the GCS)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as fh:
                argv = fh.read().decode(errors="replace").split("\0")
        except OSError:
            continue
        if os.path.basename(argv[0]) == "gcs_server" and f"--session-dir={session_dir}" in argv:
            found.append(argv)
    assert len(found) == 1, found
    (arg,) = [a for a in found[0] if a.startswith("--config_list=")]
    return json.loads(base64.b64decode(arg.split("=", 1)[1]))
