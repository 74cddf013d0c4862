"""``recap estimate`` prices a SWE-bench Verified sweep on a machine that cannot run it yet (issue 36
item 6): the Docker daemon down or the images missing are listed as what a run still needs, not
refused; ``recap run`` still refuses."""

from __future__ import annotations

import re

import pytest

from workers.envs.swe_verified import images

from .conftest import write_jsonl

SWEEP = """run: verified
output: {out}
models:
  - model: openai/gpt-4.1-2025-04-14
    api_key_env: RECAP_TEST_NO_SUCH_KEY
    prices: {{input: 2.00, cached_input: 0.50, output: 8.00}}
methods:
  - {{method: recap, label: recap, profile: released, settings: {{max_episode_cost_usd: 10.0}}}}
  - {{method: mini_swe, label: react, profile: released}}
environments:
  - benchmark: swe-verified
    tasks: [all]
    options: {{max_commands: 250}}
run_cap_usd: 100.0
"""


@pytest.fixture
def fetched(tmp_path, records, cache, capsys):
    import pipeline.cli as cli

    src = write_jsonl(tmp_path / "verified.jsonl", records)
    assert cli.main(["data", "fetch", "swebench-verified", "--from", str(src), "--subset"]) == 0
    capsys.readouterr()
    spec = tmp_path / "sweep.yaml"
    spec.write_text(SWEEP.format(out=tmp_path / "out"))
    return spec


def _table_rows(out: str) -> dict[str, list[str]]:
    rows = {}
    for line in out.splitlines():
        cells = [c.strip() for c in line.strip("│ ").split("│")]
        if len(cells) == 6 and cells[0] in ("recap", "react"):
            rows[cells[0]] = cells
    return rows


def _needs(out: str) -> list[str]:
    lines = out.splitlines()
    if "a run still needs (recap run refuses until then):" not in lines:
        return []
    return [x.removeprefix("  - ") for x in lines[lines.index("a run still needs (recap run refuses until then):") + 1 :]]


def test_estimate_with_the_docker_daemon_down_prices_and_lists_what_a_run_needs(fetched, tmp_path, capsys, monkeypatch):
    import pipeline.cli as cli

    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path / 'no-daemon.sock'}")
    assert cli.main(["estimate", str(fetched)]) == 0
    cap = capsys.readouterr()
    rows = _table_rows(cap.out)
    assert set(rows) == {"recap", "react"}
    assert [rows[m][2] for m in ("recap", "react")] == ["3", "3"]  # every instance priced
    for cells in rows.values():
        low, high = (float(x) for x in cells[5].split(" - "))
        assert 0 < low <= high
    assert "estimate for run verified: 6 units" in cap.out
    assert _needs(cap.out) == [
        "environments[0] (swe-verified): the Docker daemon (unreachable: start it, `sudo systemctl start docker` "
        "or `sudo dockerd &`)",
        "environments[0] (swe-verified): 3 instance images (not checked without the daemon; pull them (docker pull "
        "swebench/sweb.eval.x86_64.<id>:latest) or build them with the SWE-bench harness (python -m "
        "swebench.harness.prepare_images))",
    ]
    assert not (tmp_path / "out").exists()


def test_estimate_with_images_missing_counts_them(fetched, capsys, monkeypatch):
    import pipeline.cli as cli

    present = {images.local_image("fixture__offbyone-1"), "python:3.11"}
    monkeypatch.setattr("workers.envs.swe_verified.benchmark.local_images", lambda: present)
    assert cli.main(["estimate", str(fetched)]) == 0
    out = capsys.readouterr().out
    assert set(_table_rows(out)) == {"recap", "react"}
    needs = _needs(out)
    assert len(needs) == 1
    assert re.fullmatch(
        r"environments\[0\] \(swe-verified\): 2 instance images of 3 \(pull them .*; "
        r"first: swebench/sweb\.eval\.x86_64\.fixture_1776_format-1:latest\)",
        needs[0],
    )


def test_run_still_refuses_with_the_daemon_down(fetched, tmp_path, capsys, monkeypatch):
    import pipeline.cli as cli

    monkeypatch.setenv("DOCKER_HOST", f"unix://{tmp_path / 'no-daemon.sock'}")
    monkeypatch.setenv("RECAP_TEST_NO_SUCH_KEY", "sk-test")
    assert cli.main(["run", str(fetched), "--dry-run"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("recap: error: sweep.yaml: environments[0] (swe-verified): ")
    assert "Docker daemon is unreachable" in err
