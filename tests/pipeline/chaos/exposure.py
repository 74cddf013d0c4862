"""Secrets and sockets: an API key never reaches a file, a log line or the network beyond the
loopback.

One ``recap run`` process with its own local Ray (dashboard on, session folder under a
private ``RAY_TMPDIR``) plays a sweep with two models on the fake server, which requires a
key: one with the right key, one with a wrong key that the server echoes back in its 401
error (as real providers do). Checked:

* neither key appears in any file under the run folder, in the Ray session folder (logs of
  every Ray process, the runtime-env agent's included), nor in the command's stdout/stderr;
* the echoed key was scrubbed (``[REDACTED]``) in the ``llm_calls`` error rows;
* while the sweep runs, every listening socket of the driver and of every process it started
  (Ray's GCS, raylet, dashboard, agents, workers) and of this process (the fake servers) is
  bound to the loopback.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

from tests.pipeline.chaos.harness import (
    FAKE_KEY,
    KEY_ENV,
    Lab,
    ScenarioResult,
    blocks,
    fake_model,
    rows,
    sweep,
    wait_until,
)
from tests.pipeline.chaos.procnet import Listener, listeners, process_tree

WRONG_KEY_ENV = "RECAP_CHAOS_WRONG_KEY"
WRONG_KEY = "sk-chaos-WRONGKEY-c0ffee00d15ea5e5"


def files_containing(root: Path, secrets: list[str]) -> list[str]:
    """Every regular file under ``root`` holding one of ``secrets`` (bytes compared)."""
    needles = [s.encode() for s in secrets]
    hits = []
    for folder, _dirs, names in os.walk(root):
        for name in names:
            path = Path(folder) / name
            try:
                if not path.is_file() or path.is_symlink():
                    continue
                data = path.read_bytes()
            except OSError:
                continue
            if any(n in data for n in needles):
                hits.append(str(path))
    return hits


def secrets_and_sockets(lab: Lab) -> ScenarioResult:
    res = ScenarioResult("secrets + loopback sockets")
    res.begin_run()
    server = lab.server(require_api_key=FAKE_KEY, latency_s=0.1, prefix_memory=0)
    base = lab.folder("secrets")
    out = base / "run"
    ray_tmp = Path(tempfile.mkdtemp(prefix="rs", dir="/tmp"))  # short: Ray's socket paths are length-limited
    models = fake_model(server.base_url) + fake_model(server.base_url, label="wrong-key", key_env=WRONG_KEY_ENV, max_tokens=63)
    spec = base / "sweep.yaml"
    spec.write_text(sweep(out, models, blocks(3), llm_calls=4, workers=2, extra="ray: {dashboard: true}\n"))
    env = lab.env(**{KEY_ENV: FAKE_KEY, WRONG_KEY_ENV: WRONG_KEY, "RAY_TMPDIR": str(ray_tmp)})
    proc = lab.cli(["run", str(spec), "--progress", "lines"], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: set[Listener] = set()
    try:
        wait_until(lambda: proc.poll() is not None or len(server.log) >= 2, 180, 0.1)
        for _ in range(3):  # while the sweep runs: the driver and everything it started
            if proc.poll() is not None:
                break
            seen.update(listeners(process_tree(proc.pid)))
            time.sleep(0.5)
        stdout, stderr = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        proc.kill()
        stdout, stderr = proc.communicate()
    mine = listeners(process_tree(os.getpid()))
    res.check(
        "the run ends (exit 4: the wrong-key units failed on auth, retryable)",
        proc.returncode == 4,
        f"exit {proc.returncode}: {stderr.strip()[-300:]}",
    )
    res.check(
        "no Ray error about restart arguments in the object store",
        "constructor arguments in the object store" not in stderr,
        stderr.strip()[:200],
    )
    res.check("sockets were sampled while the sweep ran", len(seen) >= 3, len(seen))
    public = sorted(str(x) for x in seen | set(mine) if not x.loopback)
    res.check("every listening socket is on the loopback", not public, public[:5])
    dashboard = [x for x in seen if "dashboard" in x.process.lower()]
    res.check(
        "the dashboard (on in this sweep) listens, on the loopback",
        dashboard and all(x.loopback for x in dashboard),
        [str(x) for x in dashboard][:3],
    )
    res.check("the wrong key reached the server (its echo was exercised)", any(c.status == 401 for c in server.log))
    res.check("the right key worked", any(c.status == 200 for c in server.log))
    errors = [r for r in rows(out, "llm_calls") if r["error_kind"] == "auth"]
    res.check(
        "the echoed key is scrubbed in the llm_calls rows",
        errors and all("[REDACTED]" in (r["error_message"] or "") for r in errors),
        len(errors),
    )
    keys = [FAKE_KEY, WRONG_KEY]
    in_run = files_containing(out, keys)
    in_ray = files_containing(ray_tmp, keys)
    in_output = [name for name, text in (("stdout", stdout), ("stderr", stderr)) if any(k in text for k in keys)]
    res.check("no file under the run folder holds a key", not in_run, in_run[:3])
    res.check("no Ray session file or log holds a key", not in_ray, in_ray[:3])
    res.check("stdout/stderr hold no key", not in_output, in_output)
    n_files = sum(len(names) for _, _, names in os.walk(ray_tmp)) + sum(len(names) for _, _, names in os.walk(out))
    res.notes.append(
        f"{n_files} files scanned, {len(in_run) + len(in_ray) + len(in_output)} with a key; "
        f"{len(seen | set(mine))} listening sockets, {len(public)} off the loopback"
    )
    shutil.rmtree(ray_tmp, ignore_errors=True)
    res.end_run()
    return res
