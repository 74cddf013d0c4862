"""The ``llama.cpp`` engine: a Ray Serve replica that runs ``python -m llama_cpp.server`` on a GGUF file.

Why a wrapper: llama.cpp's own OpenAI-compatible server (llama-cpp-python) already answers chat
completions; Serve gives it replicas, placement on the cluster, health checks and a replacement
when one dies. Each replica starts the server on a free loopback port of its node and relays
the route's requests to it.

What the real server asks of the wrapper (found running it, issue 38):

* health: ``GET /v1/models`` waits for the model's lock (``llama_cpp/server/app.py``,
  ``get_llama_proxy``), so while a completion runs it does not answer: a health check on it
  would call a busy replica dead and have Serve replace it mid-call. Ready is asked once of
  ``/v1/models`` (the weights are loaded); healthy is the process alive and its web loop
  answering ``GET /openapi.json`` (no lock), asked without blocking the replica's own loop;
* the process outlives a replica killed without its ``__del__`` (``ray.kill``, a worker's
  SIGKILL, a cluster shut down): the server runs under a small launcher whose watchdog thread
  ends it once its parent (the replica) is gone; ``__del__`` (Serve calls it on a graceful
  stop: ``serve.delete``, the session's end, Ctrl-C) terminates it and waits for it. It runs in a
  session of its own, so the terminal's Ctrl-C reaches the driver (which stops gracefully and
  lets the episodes in flight finish on it), not the server;
* the port: a free one is picked and then bound by the server; taken in between (another
  process), the server exits at once and the replica starts it again on another port
  (:data:`PORT_TRIES`);
* its settings: the server reads environment variables over its options (``HOST``, ``PORT``,
  ``CONFIG_FILE``, and each setting by its name: ``API_KEY`` would make it refuse the route's
  calls); the launcher removes them before the server starts;
* its output goes to a log file beside the replica's (``$TMPDIR``), whose tail is in the
  error when it fails to start.

``engine_args`` become the server's options (``n_ctx: 4096`` -> ``--n_ctx 4096``);
``n_gpu_layers`` defaults to all layers when the replica has a GPU, ``n_threads`` and
``n_threads_batch`` to the replica's CPUs. Only where llama-cpp-python
is installed (``pip install 'llama-cpp-python[server]'``): preflight refuses the engine otherwise.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Mapping
from pathlib import Path
from typing import Any

HOST = "127.0.0.1"
#: seconds a replica waits for its server to load the weights and answer
START_TIMEOUT_S = 600.0
#: seconds the server gets to exit after SIGTERM before it is killed
STOP_GRACE_S = 10.0
#: seconds between two looks of the server's watchdog at its parent
WATCH_S = 0.5
#: starts tried when the server exits before answering (its port was taken in between)
PORT_TRIES = 3
#: the module the launcher runs (a test stands a double in for it)
SERVER_MODULE = "llama_cpp.server"
#: the launcher: a watchdog thread that ends the server when the replica that started it is gone
#: (its parent pid changes); the environment variables llama_cpp.server would read over its
#: command line removed (its settings are pydantic-settings without a prefix, so an ``API_KEY``,
#: ``MODEL`` or ``N_CTX`` of the driver's environment, which Ray's workers inherit, would set
#: them, and ``HOST``/``PORT``/``CONFIG_FILE`` override the options outright:
#: ``llama_cpp/server/__main__.py``); then the server module as ``python -m`` would run it
LAUNCHER = """import os, runpy, sys, threading, time
parent, period, module = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
def watch():
    while os.getppid() == parent:
        time.sleep(period)
    os._exit(0)
threading.Thread(target=watch, daemon=True).start()
if module == "llama_cpp.server":
    from llama_cpp.server.settings import ModelSettings, ServerSettings
    names = {"config_file", *ModelSettings.model_fields, *ServerSettings.model_fields}
    for key in [k for k in os.environ if k.lower() in names]:
        del os.environ[key]
sys.argv = [module, *sys.argv[4:]]
runpy.run_module(module, run_name="__main__", alter_sys=True)
"""


def server_command(
    gguf: str,
    served_name: str,
    port: int,
    engine_args: Mapping[str, Any],
    gpus: int,
    cpus: float = 1.0,
    *,
    module: str = SERVER_MODULE,
) -> list[str]:
    """The command line of one replica's server (under the launcher, watched from this process).
    Its threads are the CPUs Ray holds for the replica (llama.cpp's own default is half the
    node's cores, whatever the replica was given)."""
    threads = max(1, int(cpus))
    args = {"n_gpu_layers": -1 if gpus else 0, "n_threads": threads, "n_threads_batch": threads, **engine_args}
    cmd = [sys.executable, "-c", LAUNCHER, str(os.getpid()), str(WATCH_S), module]
    cmd += ["--model", gguf, "--model_alias", served_name, "--host", HOST, "--port", str(port)]
    for key, value in args.items():
        cmd += [f"--{key}", str(value).lower() if isinstance(value, bool) else str(value)]
    return cmd


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


def _get(url: str, timeout: float) -> bool:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as resp:
            return bool(resp.status == 200)
    except OSError:
        return False


def _tail(path: Path, lines: int = 5) -> str:
    try:
        text = path.read_text(errors="replace").strip().splitlines()
    except OSError:
        return ""
    return " | ".join(line.strip() for line in text[-lines:])


class LlamaCppServer:
    """The deployment's class: starts the server, relays requests, reports its health."""

    def __init__(
        self,
        served_name: str,
        gguf: str,
        engine_args: Mapping[str, Any],
        gpus: int,
        cpus: float = 1.0,
        *,
        module: str = SERVER_MODULE,
    ) -> None:
        self.proc: subprocess.Popen[bytes] | None = None
        self.session: Any = None
        fd, log = tempfile.mkstemp(prefix="llama-cpp-server-", suffix=".log")
        os.close(fd)
        self.log = Path(log)
        for _ in range(PORT_TRIES):
            self.port = _free_port()
            self.base = f"http://{HOST}:{self.port}"
            with open(self.log, "ab") as out:
                self.proc = subprocess.Popen(
                    server_command(gguf, served_name, self.port, engine_args, gpus, cpus, module=module),
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            if self._wait_started(gguf):
                return
        raise RuntimeError(f"llama_cpp.server exited at once {PORT_TRIES} times (last: {_tail(self.log)})")

    def _wait_started(self, gguf: str) -> bool:
        """Whether the server answers; False when it exited before loading (a port taken in
        between: try another); RuntimeError when it failed on the weights or took too long."""
        assert self.proc is not None
        t0 = time.monotonic()
        while not _get(self.base + "/v1/models", timeout=2):
            code = self.proc.poll()
            if code is not None:
                if "address already in use" in _tail(self.log, 20).lower():
                    return False
                raise RuntimeError(f"llama_cpp.server exited with status {code} while loading {gguf}: {_tail(self.log)}")
            if time.monotonic() - t0 > START_TIMEOUT_S:
                self._stop()
                raise RuntimeError(f"llama_cpp.server did not answer within {START_TIMEOUT_S:g}s ({gguf})")
            time.sleep(0.25)
        return True

    async def _alive(self) -> bool:
        """The process runs and its web loop answers (``/openapi.json`` takes no model lock)."""
        import aiohttp  # lazy: the replica's own dependencies

        if self.proc is None or self.proc.poll() is not None:
            return False
        try:
            async with aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=10)) as session:
                async with session.get(self.base + "/openapi.json") as resp:
                    return resp.status == 200
        except (aiohttp.ClientError, TimeoutError, OSError):
            return False

    async def __call__(self, request: Any) -> Any:
        import aiohttp  # lazy: as above
        from starlette.responses import JSONResponse, Response

        path = request.url.path
        root = request.scope.get("root_path") or ""
        sub = path[len(root) :] if root and path.startswith(root) else path
        if request.method == "GET" and sub.rstrip("/").endswith("/health"):
            ok = await self._alive()
            return JSONResponse({"status": "ok" if ok else "down"}, status_code=200 if ok else 503)
        if self.session is None:  # one connection pool per replica; no deadline: the gateway has its own
            self.session = aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=None))
        body = await request.body()
        async with self.session.request(
            request.method, self.base + sub, data=body, headers={"content-type": "application/json"}
        ) as resp:
            return Response(await resp.read(), status_code=resp.status, media_type=resp.headers.get("content-type"))

    async def check_health(self) -> None:
        """Serve's per-replica health check (async: a busy server is not a dead one)."""
        if not await self._alive():
            code = None if self.proc is None else self.proc.poll()
            raise RuntimeError(f"llama_cpp.server is not answering (exit status {code}): {_tail(self.log)}")

    def _stop(self) -> None:
        proc, self.proc = self.proc, None
        if proc is None or proc.poll() is not None:
            return
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(STOP_GRACE_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(STOP_GRACE_S)

    def __del__(self) -> None:
        self._stop()
        log = getattr(self, "log", None)
        if log is not None:
            log.unlink(missing_ok=True)


def deployment(
    served_name: str,
    gguf: str,
    engine_args: Mapping[str, Any],
    *,
    name: str,
    replicas: int,
    max_in_flight: int,
    cpus: float,
    gpus: int,
) -> Any:
    """The bound Serve application of one GGUF model."""
    from ray import serve  # lazy: Serve loads only where a sweep serves a model

    return serve.deployment(
        name=name,
        num_replicas=replicas,
        max_ongoing_requests=max_in_flight,
        ray_actor_options={"num_cpus": cpus, "num_gpus": gpus},
        health_check_period_s=5.0,
        health_check_timeout_s=30.0,
    )(LlamaCppServer).bind(served_name, gguf, dict(engine_args), gpus, cpus)
