"""TEST DOUBLE of ``python -m llama_cpp.server`` for the llama.cpp engine's process handling
(tests/workers/serving/test_llama_cpp_process.py), where llama-cpp-python is not installed.

It takes the options the engine passes (``--model --model_alias --host --port`` and any
``--key value``), answers like the real server where the engine depends on it: ``GET /v1/models``
waits for the model's lock, as the real one does (``llama_cpp/server/app.py``, ``get_llama_proxy``),
``GET /openapi.json`` does not, and ``POST /v1/chat/completions`` holds the lock for ``--hold_s``
seconds. ``--model`` naming a missing file exits with status 1, as the real server does. Like the
real one (``llama_cpp/server/__main__.py``, its pydantic-settings), ``HOST`` and ``PORT`` in the
environment override the options, and an ``API_KEY`` there makes it refuse calls without it.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path


def main(argv: list[str]) -> None:
    opts = dict(zip(argv[0::2], argv[1::2]))
    if not Path(opts["--model"]).is_file():
        print(f"ValueError: Model path does not exist: {opts['--model']}", flush=True)
        sys.exit(1)
    hold_s = float(opts.get("--hold_s", "0"))
    api_key = os.environ.get("API_KEY")
    lock = threading.Lock()
    alias = opts.get("--model_alias", opts["--model"])

    class Handler(BaseHTTPRequestHandler):
        def log_message(self, *args: object) -> None:
            pass

        def _json(self, body: dict) -> None:
            data = json.dumps(body).encode()
            self.send_response(200)
            self.send_header("content-type", "application/json")
            self.send_header("content-length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def do_GET(self) -> None:
            if self.path == "/openapi.json":
                self._json({"openapi": "3.1.0"})
            elif self.path == "/v1/models":
                with lock:
                    self._json({"object": "list", "data": [{"id": alias}]})
            else:
                self.send_error(404)

        def do_POST(self) -> None:
            if api_key is not None and self.headers.get("authorization") != f"Bearer {api_key}":
                self.send_error(401)
                return
            body = json.loads(self.rfile.read(int(self.headers["content-length"])))
            # about a token per 4 characters of the messages (the gateway rejects implausible usage)
            prompt = 1 + sum(len(str(m.get("content") or "")) for m in body.get("messages") or []) // 4
            with lock:
                time.sleep(hold_s)
                self._json(
                    {
                        "object": "chat.completion",
                        "model": body.get("model"),
                        "choices": [{"index": 0, "message": {"role": "assistant", "content": "ok"}, "finish_reason": "stop"}],
                        "usage": {"prompt_tokens": prompt, "completion_tokens": 1, "total_tokens": prompt + 1},
                    }
                )

    ThreadingHTTPServer((os.getenv("HOST", opts["--host"]), int(os.getenv("PORT", opts["--port"]))), Handler).serve_forever()


if __name__ == "__main__":
    main(sys.argv[1:])
