"""The llama.cpp engine's hold on its server process (workers/serving/llama_cpp.py), with a test
double of ``llama_cpp.server`` (tests/doubles/llama_server.py) standing in for the real one: a
replica busy with a completion is healthy (the real server's ``/v1/models`` waits for the model's
lock), a replica killed without its ``__del__`` leaves no server behind, a port taken between its
choice and its bind is replaced by another, a server that fails on its weights says why, and
``__del__`` stops the server. The real server: tests/realmodel/test_served_llama_cpp.py (slow)."""

from __future__ import annotations

import asyncio
import os
import socket
import subprocess
import sys
import textwrap
import threading
import time
import urllib.request
from pathlib import Path

import pytest

from workers.serving import llama_cpp

DOUBLE = "tests.doubles.llama_server"
REPO = Path(__file__).resolve().parents[3]


@pytest.fixture
def gguf(tmp_path: Path) -> str:
    path = tmp_path / "m.gguf"
    path.write_bytes(b"GGUF" + b"\0" * 8)
    return str(path)


@pytest.fixture(autouse=True)
def _repo_cwd(monkeypatch):
    monkeypatch.chdir(REPO)  # the launcher's `python -c` finds the double's package from here


def _running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:  # a zombie (exited, not yet reaped) is not running
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


def _gone_within(pid: int, seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if not _running(pid):
            return True
        time.sleep(0.1)
    return False


def test_a_replica_busy_with_a_completion_is_healthy_and_del_stops_its_server(gguf):
    server = llama_cpp.LlamaCppServer("smol", gguf, {"hold_s": 4}, 0, module=DOUBLE)
    assert server.proc is not None
    pid, log = server.proc.pid, server.log
    try:
        body = b'{"model": "smol", "messages": [{"role": "user", "content": "hi"}]}'
        req = urllib.request.Request(server.base + "/v1/chat/completions", data=body, method="POST")
        busy = threading.Thread(target=lambda: urllib.request.urlopen(req, timeout=30).read())
        busy.start()
        time.sleep(0.5)  # the completion holds the model's lock now
        t0 = time.monotonic()
        asyncio.run(server.check_health())  # answers while /v1/models would wait for the lock
        assert time.monotonic() - t0 < 2.0 and busy.is_alive()
        busy.join()
    finally:
        server.__del__()
    assert not _running(pid) and not log.exists()


def test_a_server_whose_replica_was_killed_ends_itself(tmp_path, gguf):
    """ray.kill or a worker's SIGKILL: no __del__ runs; the launcher's watchdog ends the server."""
    script = textwrap.dedent(
        f"""
        import sys, time
        from workers.serving import llama_cpp
        s = llama_cpp.LlamaCppServer("smol", {gguf!r}, {{}}, 0, module={DOUBLE!r})
        print(s.proc.pid, flush=True)
        time.sleep(600)
        """
    )
    replica = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        assert replica.stdout is not None
        pid = int(replica.stdout.readline())
        assert _running(pid)
        replica.kill()
        replica.wait(10)
        assert _gone_within(pid, 5.0), "the server outlived its replica"
    finally:
        if replica.poll() is None:
            replica.kill()


def test_a_port_taken_before_the_server_binds_it_is_replaced(gguf, monkeypatch):
    taken = socket.socket()
    taken.bind((llama_cpp.HOST, 0))
    taken.listen()
    free = llama_cpp._free_port()
    ports = iter([taken.getsockname()[1], free])
    monkeypatch.setattr(llama_cpp, "_free_port", lambda: next(ports))
    try:
        server = llama_cpp.LlamaCppServer("smol", gguf, {}, 0, module=DOUBLE)
        try:
            assert server.port == free
            asyncio.run(server.check_health())
        finally:
            server.__del__()
    finally:
        taken.close()


def test_a_server_failing_on_its_weights_says_why(tmp_path):
    missing = str(tmp_path / "gone.gguf")
    with pytest.raises(RuntimeError) as info:
        llama_cpp.LlamaCppServer("smol", missing, {}, 0, module=DOUBLE)
    assert str(info.value) == (
        f"llama_cpp.server exited with status 1 while loading {missing}: ValueError: Model path does not exist: {missing}"
    )


def test_the_server_command_line_threads_on_the_replica_s_cpus_and_takes_the_engine_args():
    cmd = llama_cpp.server_command("/w/m.gguf", "smol", 8123, {"n_ctx": 8192, "flash_attn": True}, 0, 2.0)
    assert cmd[:3] == [sys.executable, "-c", llama_cpp.LAUNCHER]
    assert cmd[3:6] == [str(os.getpid()), str(llama_cpp.WATCH_S), "llama_cpp.server"]
    assert cmd[6:] == [
        "--model", "/w/m.gguf", "--model_alias", "smol", "--host", "127.0.0.1", "--port", "8123",
        "--n_gpu_layers", "0", "--n_threads", "2", "--n_threads_batch", "2", "--n_ctx", "8192", "--flash_attn", "true",
    ]  # fmt: skip
    # a GPU replica offloads every layer; the engine arguments win over the defaults
    gpu = llama_cpp.server_command("/w/m.gguf", "smol", 1, {"n_threads": 6}, 1, 0.5)
    assert gpu[gpu.index("--n_gpu_layers") + 1] == "-1" and gpu[gpu.index("--n_threads") + 1] == "6"
    assert gpu[gpu.index("--n_threads_batch") + 1] == "1"


def test_the_server_does_not_read_the_replica_s_environment_over_its_options(tmp_path, gguf, monkeypatch):
    """llama_cpp.server takes HOST, PORT and each setting (API_KEY ...) from the environment, which
    a replica inherits from the driver: the launcher removes them. A stand-in ``llama_cpp.server``
    package (the double, with settings classes naming those fields) shows it."""
    fake = tmp_path / "site" / "llama_cpp" / "server"
    fake.mkdir(parents=True)
    (fake.parent / "__init__.py").write_text("")
    (fake / "__init__.py").write_text("")
    (fake / "__main__.py").write_text("import sys\nfrom tests.doubles.llama_server import main\nmain(sys.argv[1:])\n")
    (fake / "settings.py").write_text(
        "class ModelSettings:\n    model_fields = {'model': None, 'n_ctx': None}\n"
        "class ServerSettings:\n    model_fields = {'host': None, 'port': None, 'api_key': None}\n"
    )
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path / "site"), str(REPO)]))
    monkeypatch.setenv("API_KEY", "sk-of-something-else")
    monkeypatch.setenv("PORT", "1")
    monkeypatch.setenv("HOST", "0.0.0.0")
    monkeypatch.setattr(llama_cpp, "START_TIMEOUT_S", 30.0)  # a server listening elsewhere: fail in 30 s
    server = llama_cpp.LlamaCppServer("smol", gguf, {}, 0)  # module: llama_cpp.server (the stand-in)
    try:
        body = b'{"model": "smol", "messages": [{"role": "user", "content": "hi"}]}'
        req = urllib.request.Request(server.base + "/v1/chat/completions", data=body, method="POST")
        with urllib.request.urlopen(req, timeout=30) as resp:
            assert resp.status == 200  # on the port the replica chose, without a key
    finally:
        server.__del__()
