"""What a local cluster's raylet starts as its runtime-environment agent when the dashboard is off:
Ray's agent, started only once the raylet first asks it for something.

Why: Ray's runtime-env agent (``ray/_private/runtime_env/agent/main.py``, ~48 MB PSS: Ray,
aiohttp, protobuf and every runtime-env plugin) is asked for nothing while every worker starts
without a runtime_env - the raylet starts those directly - which is how a run's actors start on a
cluster :func:`pipeline.raysetup.init_ray` started (:func:`pipeline.raysetup.actor_runtime_env`
is None there). Some still start with one (a variable changed since the start, a run service's
name), so the agent must answer when asked, but it need not exist before (issue 37, item 3).

So this process - standard library only, started with ``python -I -S`` - binds the agent's port
(the address and port Ray's command line asks for; port 0: a free one), publishes it in the port
file the raylet reads at its start, and waits. When a connection arrives it becomes Ray's agent:
it closes its socket and ``exec``\\ s Ray's own command, with the bound port in place of the one
asked for. Same process id (the raylet, which shares its fate with the agent, watches that id),
same environment and standard streams. The raylet's request that woke it is cut off unanswered,
which the raylet retries every second until the agent answers
(``src/ray/raylet/runtime_env_agent_client.cc``: network errors are retried until
``agent_register_timeout_ms``); Ray's agent binds the port again (``SO_REUSEADDR``) and publishes
the same value. Until then, this process leaves when its parent - the raylet - is gone.

Command line (built by :func:`pipeline.raysetup._lean_head` from Ray's own agent command):
``--port-file=PATH --session-dir=DIR -- RAY_AGENT_COMMAND...``; the address and port come from
Ray's command (``--node-ip-address=``, ``--runtime-env-agent-port=``). ``--session-dir`` is only
there so that :func:`pipeline.local_cluster.processes` finds this process by its folder.
"""

from __future__ import annotations

import os
import select
import socket
import sys

#: seconds between two looks at whether the raylet is still this process's parent
POLL_S = 1.0
#: Ray's agent options this process reads and rewrites
ADDRESS_ARG = "--node-ip-address="
PORT_ARG = "--runtime-env-agent-port="


def _value(command: list[str], prefix: str) -> str | None:
    found = [arg[len(prefix) :] for arg in command if arg.startswith(prefix)]
    return found[-1] if found else None


def bind(command: list[str]) -> socket.socket:
    """A listening socket on the address and port Ray's agent command asks for (as Ray's agent
    binds it: ``SO_REUSEADDR``, the first address ``getaddrinfo`` gives)."""
    host = _value(command, ADDRESS_ARG) or "127.0.0.1"
    port = int(_value(command, PORT_ARG) or 0)
    family, kind, proto, _, address = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(address)
    sock.listen(64)
    return sock


def publish(path: str, port: int) -> None:
    """Write the port file whole or not at all (the raylet reads it as soon as it exists)."""
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w") as fh:
        fh.write(str(port))
    os.replace(tmp, path)


def wait_for_a_caller(sock: socket.socket, parent: int, poll_s: float = POLL_S) -> bool:
    """True once a connection waits on ``sock``; False when ``parent`` is no longer this
    process's parent (the raylet died: this process was re-parented)."""
    while os.getppid() == parent:
        ready, _, _ = select.select([sock], [], [], poll_s)
        if ready:
            return True
    return False


def agent_command(command: list[str], port: int) -> list[str]:
    """Ray's agent command with the bound port in place of the one it asked for."""
    return [f"{PORT_ARG}{port}" if arg.startswith(PORT_ARG) else arg for arg in command]


def main(argv: list[str]) -> int:
    """Bind, publish, wait, then become Ray's agent; 2 and one line on stderr for a bad command line."""
    if "--" not in argv:
        print("lazy_runtime_env_agent: no Ray agent command after --", file=sys.stderr)
        return 2
    cut = argv.index("--")
    options, command = argv[:cut], argv[cut + 1 :]
    port_file = _value(options, "--port-file=")
    if not port_file or not command:
        print("lazy_runtime_env_agent: --port-file and a Ray agent command are needed", file=sys.stderr)
        return 2
    parent = os.getppid()
    sock = bind(command)
    port = sock.getsockname()[1]
    publish(port_file, port)
    if not wait_for_a_caller(sock, parent):
        return 0
    sock.close()  # the caller's pending connection is reset: the raylet retries it
    os.execv(command[0], agent_command(command, port))
    return 1  # not reached: execv replaces this process or raises


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
