"""FEVER offline (issue 36 item 11): the Wikipedia stand-in served by a command until stopped, and a
snapshot replayed without repeating the ``wikipedia_url`` its run recorded."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

from workers.envs.fever.benchmark import BENCHMARK
from workers.envs.fever.pages import write_pages
from workers.envs.fever.ratelimit import TokenBucket

ROOT = Path(__file__).resolve().parents[4]
ACTIONS = ["search[Nikolaj Coster-Waldau]", "search[Nikolaj]", "lookup[Copenhagen]", "search[Coster-Waldau]"]


def _serving(argv: list[str]) -> tuple[subprocess.Popen[str], str]:
    """The stand-in started by ``argv`` and its base URL (its first line, read as it is printed)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), LITELLM_LOCAL_MODEL_COST_MAP="True")
    proc = subprocess.Popen([sys.executable, *argv], cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    first = proc.stdout.readline()
    assert first.startswith("FEVER Wikipedia stand-in on http://127.0.0.1:"), (first, proc.stderr.read() if proc.poll() else "")
    return proc, first.split()[4]


@pytest.mark.parametrize(
    "argv, sig",
    [
        (["-m", "pipeline.cli", "env", "standin", "fever", "--port", "0"], signal.SIGTERM),
        (["-m", "pipeline.cli", "env", "standin", "fever", "--port", "0"], signal.SIGINT),
        (["-m", "workers.envs.fever.standin", "--port", "0"], signal.SIGINT),
    ],
    ids=["recap-sigterm", "recap-sigint", "module-sigint"],
)
def test_the_standin_serves_until_stopped_and_stops_cleanly(argv, sig):
    proc, base = _serving(argv)
    try:
        with urllib.request.urlopen(f"{base}/w/index.php?search=Nikolaj+Coster-Waldau", timeout=30) as answer:
            assert answer.status == 200
            assert '<h1 id="firstHeading">Nikolaj Coster-Waldau</h1>' in answer.read().decode()
        assert proc.stdout is not None
        assert proc.stdout.readline().startswith("answers: ")
        assert proc.stdout.readline() == "stop with Ctrl-C (SIGINT) or SIGTERM\n"
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert (proc.returncode, out, err) == (0, "stopped after 1 request\n", "")


def test_a_taken_port_is_one_line_and_status_2(capsys):
    import socket

    from pipeline.cli import main

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert main(["env", "standin", "fever", "--port", str(port)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"recap: error: cannot listen on 127.0.0.1:{port}: ") and err.count("\n") == 1


def test_a_snapshot_replays_without_repeating_the_recorded_wikipedia_url(claims_dir, standin, store, tmp_path):
    env = BENCHMARK.make(
        "fever/1001",
        data_dir=str(claims_dir),
        wikipedia_url=standin.base_url,
        limiter=TokenBucket(1000.0, 1000),
        page_store=store,
    )
    env.reset()
    recorded = [env.step(a).observation for a in ACTIONS]
    write_pages(store.records, tmp_path / "run" / "wiki_pages.parquet")
    base, served = standin.base_url, len(standin.requests)
    standin.stop()
    replay = BENCHMARK.make("fever/1001", data_dir=str(claims_dir), wikipedia=f"snapshot:{tmp_path / 'run'}")
    assert replay.wikipedia_url == base  # read from the snapshot, not the real site's default
    replay.reset()
    assert [replay.step(a).observation for a in ACTIONS] == recorded
    assert len(standin.requests) == served


def test_a_snapshot_of_several_servers_asks_which(claims_dir, tmp_path):
    from workers.envs.fever.pages import PageRecord, sha256_hex

    body = b"<p>a b c</p>"
    rows = [
        PageRecord(f"{base}/w/index.php?search=A", sha256_hex(body), 200, "2024-03-01T10:00:00Z", body, "utf-8", f"{base}/wiki/A")
        for base in ("http://one.example", "http://two.example")
    ]
    write_pages(rows, tmp_path / "snap" / "wiki_pages.parquet")
    with pytest.raises(
        ValueError, match=r"holds pages of 2 servers \(http://one.example, http://two.example\); give wikipedia_url"
    ):
        BENCHMARK.make("fever/1001", data_dir=str(claims_dir), wikipedia=f"snapshot:{tmp_path / 'snap'}")
    env = BENCHMARK.make(
        "fever/1001", data_dir=str(claims_dir), wikipedia=f"snapshot:{tmp_path / 'snap'}", wikipedia_url="http://two.example"
    )
    assert env.wikipedia_url == "http://two.example"


def test_the_readme_trajectory_replays_on_the_standin(standin, tmp_path, capsys):
    """The README's FEVER trajectory is an offline run as it stands there: a NOT ENOUGH INFO claim
    finished NOT ENOUGH INFO for reward 1 (it once showed REFUTES scoring 1 on that claim)."""
    import json
    import re

    from pipeline.cli import main

    readme = (ROOT / "README.md").read_text()
    block = re.search(r'```json\n(\{"benchmark": "fever".*?)\n```', readme, re.S)
    assert block is not None
    trajectory = json.loads(block.group(1))
    assert trajectory["steps"][-1]["action"] == "finish[NOT ENOUGH INFO]"
    path = tmp_path / "trajectory.json"
    path.write_text(json.dumps(trajectory))
    argv = ["env", "replay", str(path), "--option", f"wikipedia_url={standin.base_url}"]  # the claims: ../shared/data/fever
    assert main(argv) == 0, capsys.readouterr()
    assert capsys.readouterr().out.strip().endswith("identical")
