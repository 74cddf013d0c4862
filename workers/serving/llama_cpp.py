"""The ``llama.cpp`` engine: a Ray Serve replica that runs ``python -m llama_cpp.server`` on a GGUF file.

Why a wrapper: llama.cpp's own OpenAI-compatible server (llama-cpp-python) already answers chat
completions; Serve gives it replicas, placement on the cluster, health checks and a replacement
when one dies. Each replica starts the server on a free loopback port of its node and relays
the route's requests to it; its health is the server answering ``GET /v1/models``.

``engine_args`` become the server's options (``n_ctx: 4096`` -> ``--n_ctx 4096``);
``n_gpu_layers`` defaults to all layers when the replica has a GPU. Only where llama-cpp-python
is installed (``pip install 'llama-cpp-python[server]'``): preflight refuses the engine otherwise.
"""

from __future__ import annotations

import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from typing import Any

HOST = "127.0.0.1"
#: seconds a replica waits for its server to load the weights and answer
START_TIMEOUT_S = 600.0


def server_command(gguf: str, served_name: str, port: int, engine_args: Mapping[str, Any], gpus: int) -> list[str]:
    """The command line of one replica's server."""
    args = {"n_gpu_layers": -1 if gpus else 0, **engine_args}
    cmd = [
        sys.executable,
        "-m",
        "llama_cpp.server",
        "--model",
        gguf,
        "--model_alias",
        served_name,
        "--host",
        HOST,
        "--port",
        str(port),
    ]
    for key, value in args.items():
        cmd += [f"--{key}", str(value).lower() if isinstance(value, bool) else str(value)]
    return cmd


def _free_port() -> int:
    with socket.socket() as s:
        s.bind((HOST, 0))
        return int(s.getsockname()[1])


class LlamaCppServer:
    """The deployment's class: starts the server, relays requests, reports its health."""

    def __init__(self, served_name: str, gguf: str, engine_args: Mapping[str, Any], gpus: int) -> None:
        self.port = _free_port()
        self.proc = subprocess.Popen(server_command(gguf, served_name, self.port, engine_args, gpus))
        self.base = f"http://{HOST}:{self.port}"
        deadline = time.monotonic() + START_TIMEOUT_S
        while not self._answers():
            if self.proc.poll() is not None:
                raise RuntimeError(f"llama_cpp.server exited with status {self.proc.returncode} while loading {gguf}")
            if time.monotonic() > deadline:
                raise RuntimeError(f"llama_cpp.server did not answer within {START_TIMEOUT_S:g}s")
            time.sleep(0.5)

    def _answers(self) -> bool:
        import urllib.request

        try:
            with urllib.request.urlopen(self.base + "/v1/models", timeout=2) as resp:
                return bool(resp.status == 200)
        except OSError:
            return False

    async def __call__(self, request: Any) -> Any:
        import aiohttp  # lazy: the replica's own dependencies
        from starlette.responses import JSONResponse, Response

        path = request.url.path
        root = request.scope.get("root_path") or ""
        sub = path[len(root) :] if root and path.startswith(root) else path
        if request.method == "GET" and sub.rstrip("/").endswith("/health"):
            return JSONResponse(
                {"status": "ok"} if self._answers() else {"status": "down"}, status_code=200 if self._answers() else 503
            )
        body = await request.body()
        async with aiohttp.ClientSession() as session:
            async with session.request(
                request.method, self.base + sub, data=body, headers={"content-type": "application/json"}
            ) as resp:
                return Response(await resp.read(), status_code=resp.status, media_type=resp.headers.get("content-type"))

    def check_health(self) -> None:
        if self.proc.poll() is not None or not self._answers():
            raise RuntimeError("llama_cpp.server is not answering")

    def __del__(self) -> None:
        proc = getattr(self, "proc", None)
        if proc is not None and proc.poll() is None:
            proc.terminate()


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
    )(LlamaCppServer).bind(served_name, gguf, dict(engine_args), gpus)
