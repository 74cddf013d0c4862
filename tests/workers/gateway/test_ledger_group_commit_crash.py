"""Group-committed reservations under SIGKILL: no call reaches the provider before its
reservation is on disk, and a restart from what was on disk keeps the cap.

A child gateway (this module run as a script) calls the fake server with group commit on. Its
``fdatasync`` of the ledger journal is wrapped: after each real sync it saves the journal's
synced prefix as a *disk image* - what a machine crash would leave - and the ``hold``-th sync
first announces itself and sleeps, so the parent SIGKILLs the child while a batch of
reservations is written but not yet durable. Then:

* every request the server received has its reservation in the disk image;
* the batch being committed at the kill is in the journal but was never sent;
* a gateway restarted from the disk image (the machine-crash case, settlements lost) charges at
  least what the provider billed, and calling on until refused never bills past the cap.
"""

from __future__ import annotations

import asyncio
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

from recap.llm import LLMError
from workers.gateway.core import DeploymentGateway
from workers.gateway.ledger import JOURNAL_NAME
from workers.llm.providers import DeploymentConfig

REPO = Path(__file__).resolve().parents[3]
MODEL = "openai/fake-gpt"


def _config(url: str, concurrency: int) -> DeploymentConfig:
    return DeploymentConfig(model=MODEL, api_base=url, max_concurrency=concurrency, params={"max_tokens": 20})


def _reserved_keys(data: bytes) -> dict[int, str]:
    """rid -> call key of every complete reserve line."""
    out = {}
    for line in data.split(b"\n"):
        if line.strip():
            entry = json.loads(line)
            if entry["op"] == "reserve":
                out[entry["rid"]] = entry["key"]
    return out


def test_no_call_is_sent_before_its_reservation_is_durable_and_a_crash_keeps_the_cap(fake_server, run_dir):
    from .test_hostile_provider import true_bill_pico

    server = fake_server(latency_s=0.05, keep_bodies=True)
    cap = 0.003
    image = run_dir.parent / "disk-image.jsonl"
    hold = 6
    child = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "tests.workers.gateway.test_ledger_group_commit_crash",
            str(run_dir),
            server.base_url,
            str(cap),
            str(image),
            str(hold),
        ],
        cwd=REPO,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    ok = 0
    try:
        for line in child.stdout:  # type: ignore[union-attr]
            ok += line.startswith("OK ")
            if line.startswith(("HOLD", "DONE")):  # DONE: the hold-th sync never came
                break
    finally:
        child.send_signal(signal.SIGKILL)
        child.wait(30)
    assert ok > 0

    journal = (run_dir / JOURNAL_NAME).read_bytes()
    on_disk = _reserved_keys(image.read_bytes())
    written = _reserved_keys(journal)
    sent = {f"ep#{body['messages'][0]['content'].split()[-1]}" for body in server.bodies}
    # the batch being committed when the process died: written, not durable, not sent
    pending = {key for rid, key in written.items() if rid not in on_disk}
    assert pending and not pending & sent
    assert sent <= set(on_disk.values())  # nothing reached the provider without a durable reservation

    # a machine crash leaves only the disk image: restart from it and spend until refused
    crashed = run_dir.parent / "after-crash"
    shutil.copytree(run_dir, crashed)
    shutil.copyfile(image, crashed / JOURNAL_NAME)
    billed_before = true_bill_pico(server)
    gw = DeploymentGateway(_config(server.base_url, 8), run_dir=crashed, run_id="kill-test", run_cap_usd=cap)
    server.config.latency_s = 0.0

    async def go():
        restored = await gw.budget.stats()
        results = await asyncio.gather(*[gw.complete(_request(1000 + i)) for i in range(150)], return_exceptions=True)
        final = await gw.budget.stats()
        await gw.aclose()
        return restored, results, final

    restored, results, final = asyncio.run(go())
    assert restored["restored_orphans"] >= len(on_disk) - sum(1 for _ in _settled(image.read_bytes()))
    assert restored["spent_pico"] >= billed_before  # never less than the provider billed
    refused = [r for r in results if isinstance(r, LLMError)]
    assert refused and {e.kind for e in refused} == {"budget"}
    assert true_bill_pico(server) <= round(cap * 10**12) and final["spent_usd"] <= cap


def _settled(data: bytes):
    for line in data.split(b"\n"):
        if line.strip() and json.loads(line)["op"] == "settle":
            yield line


def _request(i: int):
    from tests.doubles.llm_requests import make_request

    return make_request(i)


# ---- the child process ----------------------------------------------------------------------
def _wrap_fdatasync(journal_path: Path, image: Path, hold: int) -> None:
    """Save the synced prefix of the ledger journal after each of its fdatasyncs; announce and
    stall the ``hold``-th one (its batch is written, not yet on disk)."""
    real = os.fdatasync
    count = 0

    def wrapped(fd: int) -> None:
        nonlocal count
        if os.readlink(f"/proc/self/fd/{fd}") != str(journal_path):
            return real(fd)
        count += 1
        size = os.fstat(fd).st_size
        if count == hold:
            print("HOLD", flush=True)
            time.sleep(3600)  # killed here
        real(fd)
        tmp = image.with_suffix(".tmp")
        tmp.write_bytes(os.pread(fd, size, 0))
        os.replace(tmp, image)

    os.fdatasync = wrapped


async def _child(run_dir: str, url: str, cap_usd: float, image: str, hold: int) -> None:
    from tests.doubles.llm_requests import make_request

    _wrap_fdatasync((Path(run_dir) / JOURNAL_NAME).resolve(), Path(image), hold)
    gw = DeploymentGateway(_config(url, 4), run_dir=run_dir, run_id="kill-test", run_cap_usd=cap_usd)

    async def one(i: int) -> None:
        resp = await gw.complete(make_request(i))
        print(f"OK {i} {resp.cost_usd}", flush=True)

    await asyncio.gather(*[one(i) for i in range(40)], return_exceptions=True)
    print("DONE", flush=True)
    await asyncio.sleep(3600)


if __name__ == "__main__":
    asyncio.run(_child(sys.argv[1], sys.argv[2], float(sys.argv[3]), sys.argv[4], int(sys.argv[5])))
