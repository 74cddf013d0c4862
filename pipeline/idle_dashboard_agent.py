"""What a local cluster's raylet starts in place of Ray's dashboard agent when the dashboard is off.

Why: the raylet of every Ray node starts a dashboard agent (``ray/dashboard/agent.py``) and shares
its fate - the raylet exits when the agent does (``src/ray/raylet/agent_manager.cc``: "The raylet
fate shares with the agent") - and waits, before it registers with the GCS, for the three ports
the agent publishes as files in the session folder (metrics agent, metrics export, HTTP listen
port). Ray's agent is a Python process importing Ray, grpc, aiohttp and every dashboard module it
can find - even the "minimal" one that :func:`pipeline.raysetup._lean_head` asks for walks and
imports them all, then polls for a dashboard that is not there: ~78 MB PSS of a run's fixed
memory (issue 37, item 3; ``bench/density.py --by-role``). With the dashboard off and metrics
collection off (``raysetup.SYSTEM_CONFIG``) a sweep uses none of it: this process does what the
raylet needs and nothing more - it publishes the three ports as unused (``-1``, what Ray's minimal
agent writes for the services it does not run) and stays until the raylet goes, on the standard
library alone (started with ``python -I -S``: no site packages, no project import).

Command line (built by :func:`pipeline.raysetup._lean_head` from Ray's own agent command):
``--port-file=PATH`` (one per port, full path), ``--session-dir=DIR`` (only so that
:func:`pipeline.local_cluster.processes` finds this process among the cluster's by its folder).
Exits when its parent - the raylet - is gone, or on SIGTERM (the raylet's own shutdown).
"""

from __future__ import annotations

import os
import sys
import time

#: seconds between two looks at whether the raylet is still this process's parent
POLL_S = 1.0
#: the value Ray's agents write for a service they do not run (``ray/dashboard/agent.py``)
UNUSED_PORT = "-1"


def publish_unused(paths: list[str]) -> None:
    """Write each port file as unused, whole or not at all (a temp file renamed into place: the
    raylet reads the file as soon as it exists)."""
    for path in paths:
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "w") as fh:
            fh.write(UNUSED_PORT)
        os.replace(tmp, path)


def wait_for_parent(parent: int, poll_s: float = POLL_S) -> None:
    """Return once ``parent`` is no longer this process's parent (it died: the process was
    re-parented). Not by reading stdin: the raylet hands its agents a pipe only when Ray's
    pipe-based health check is on; otherwise stdin is the driver's (a terminal)."""
    while os.getppid() == parent:
        time.sleep(poll_s)


def main(argv: list[str]) -> int:
    """Publish the ports named by ``--port-file=`` arguments unused, then wait for the raylet;
    2 and one line on stderr without any."""
    ports = [a.split("=", 1)[1] for a in argv if a.startswith("--port-file=")]
    if not ports:
        print("idle_dashboard_agent: no --port-file given", file=sys.stderr)
        return 2
    parent = os.getppid()
    publish_unused(ports)
    wait_for_parent(parent)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
