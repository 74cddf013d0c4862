"""Each bad input: one line on stderr, exit status 2, before any model call, nothing written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.store import RunStore

REPO = Path(__file__).resolve().parents[3]

GOOD = """run: bad-inputs
output: {out}
models:
  - model: offline/expert
methods:
  - method: recap
environments:
  - benchmark: blocksworld
    tasks: ["3"]
"""


def run_cli(tmp_path: Path, spec_text: str, capsys, *extra: str) -> tuple[int, list[str], Path]:
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(spec_text.replace("{out}", str(out)))
    code = main(["run", str(spec), "--progress", "off", *extra])
    err = capsys.readouterr().err.strip().splitlines()
    return code, err, out


CASES = [
    (
        "unknown environment",
        ("benchmark: blocksworld", "benchmark: kitchen"),
        "recap: error: sweep.yaml: environments[0]: unknown benchmark 'kitchen'; known: blocksworld, robotouille, alfworld, fever, swe, swe-verified",
    ),
    (
        "unknown task",
        ('tasks: ["3"]', 'tasks: ["12"]'),
        "recap: error: sweep.yaml: environments[0]: blocksworld task '12': no blocksworld instance matches '12'; sizes [3, 4, 5], e.g. blocksworld/3@1",
    ),
    (
        "unknown instance",
        ('tasks: ["3"]', "instances: [blocksworld/banana]"),
        "recap: error: sweep.yaml: environments[0]: unknown blocksworld instance 'blocksworld/banana'; use blocksworld/<n>@<seed> with 2 <= n <= 8",
    ),
    (
        "unknown method",
        ("- method: recap", "- method: recapp"),
        "recap: error: sweep.yaml: methods[0] (recapp): unknown method 'recapp'; known: act, adapt, cot, mini_swe, react, recap, standard",
    ),
    (
        "unknown method setting",
        ("- method: recap", "- method: react\n    settings: {max_level: 3}"),
        None,
    ),  # message built by the baselines module; checked for shape below
    (
        "malformed YAML",
        ("  - method: recap", "  - method: recap\n   oops: ["),
        "recap: error: sweep.yaml: malformed YAML at line 7, column 4: expected <block end>, but found '<block mapping start>'",
    ),
    (
        "negative price",
        ("- model: offline/expert", "- model: offline/expert\n    prices: {input: 1.0, output: -2.0}"),
        "recap: error: sweep.yaml: models[0].prices.output: -2 is out of range [0, 10000]",
    ),
    (
        "missing price with a cap",
        ("- model: offline/expert", "- model: openai/no-such-model\n    api_key_env: RECAP_TEST_KEY\n    cap_usd: 1"),
        "recap: error: sweep.yaml: models[0] (openai/no-such-model) has a model cap but no price: no price for model(s) "
        "openai/no-such-model: add them to workers/pricing/prices.yaml or pass a price override (USD per million tokens: input, cached_input, cache_write, output)",
    ),
    (
        "unknown offline option",
        ("- model: offline/expert", "- model: offline/expert\n    options: {error_rate: 0.1}"),
        "recap: error: sweep.yaml: models[0] (offline/expert): unknown offline model option(s) ['error_rate']",
    ),
    (
        "both sampling seed keys",
        ('    tasks: ["3"]', '    tasks: ["3"]\nseeds: [0]\nsampling_seeds: [0]'),
        "recap: error: sweep.yaml: give sampling_seeds or its old name seeds, not both",
    ),
    (
        "both noise seed options",
        ("- model: offline/expert", "- model: offline/expert\n    options: {seed: 1, noise_seed: 1}"),
        "recap: error: sweep.yaml: models[0] (offline/expert): give noise_seed or its old name seed, not both",
    ),
    (
        "unknown generation param",
        ("- model: offline/expert", "- model: offline/expert\n    params: {temprature: 0.1}"),
        "recap: error: sweep.yaml: models[0] (offline/expert): params: unknown generation param(s) ['temprature']; allowed: "
        "['frequency_penalty', 'logit_bias', 'max_tokens', 'n', 'presence_penalty', 'response_format', 'seed', 'stop', 'temperature', 'top_p']",
    ),
]


@pytest.mark.parametrize("name, change, message", CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path, capsys, name, change, message):
    code, err, out = run_cli(tmp_path, GOOD.replace(*change), capsys)
    assert code == 2
    assert len(err) == 1
    if message is None:
        assert err[0].startswith("recap: error: sweep.yaml: methods[0] (react): ")
        assert "max_level" in err[0]
    else:
        assert err[0] == message
    assert not out.exists()


def test_missing_api_key_default_variable(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("OPENAI_API_KEY", raising=False)
    code, err, out = run_cli(tmp_path, GOOD.replace("- model: offline/expert", "- model: openai/gpt-4o"), capsys)
    assert (code, err) == (
        2,
        [
            "recap: error: sweep.yaml: models[0] (openai/gpt-4o): API key missing: set OPENAI_API_KEY "
            "(or name another variable with api_key_env)"
        ],
    )
    assert not out.exists()


def test_missing_api_key_named_variable(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("RECAP_TEST_KEY", raising=False)
    spec = GOOD.replace("- model: offline/expert", "- model: openai/gpt-4o\n    api_key_env: RECAP_TEST_KEY")
    code, err, out = run_cli(tmp_path, spec, capsys)
    assert (code, err) == (2, ["recap: error: sweep.yaml: models[0] (openai/gpt-4o): API key variable RECAP_TEST_KEY is not set"])
    assert not out.exists()


def test_output_folder_of_another_run(tmp_path, capsys):
    out = tmp_path / "out"
    ident = RunStore(out).create_identity("someone-else")
    before = sorted(p.name for p in out.iterdir())
    code, err, _ = run_cli(tmp_path, GOOD, capsys)
    assert code == 2
    assert err == [
        f"recap: error: output folder {out} holds run 'someone-else' (run_id {ident.run_id}), not 'bad-inputs'; "
        "choose another output folder or use the same run name"
    ]
    assert sorted(p.name for p in out.iterdir()) == before


def test_missing_spec_file_and_run_folder(tmp_path, capsys):
    assert main(["run", str(tmp_path / "nope.yaml")]) == 2
    assert capsys.readouterr().err.strip() == f"recap: error: sweep file '{tmp_path / 'nope.yaml'}' does not exist"
    for cmd in ("status", "resume"):
        assert main([cmd, str(tmp_path / "nothing")]) == 2
        assert capsys.readouterr().err.strip() == f"recap: error: run folder {tmp_path / 'nothing'} does not exist"
    assert not (tmp_path / "nothing").exists()


def test_real_process_exit_status(tmp_path):
    """The console entry as a process: exit status 2 and one stderr line."""
    spec = tmp_path / "sweep.yaml"
    spec.write_text(GOOD.replace("{out}", str(tmp_path / "out")).replace('tasks: ["3"]', "tasks: [3"))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    r = subprocess.run(
        [sys.executable, "-m", "pipeline.cli", "run", str(spec)], capture_output=True, text=True, env=env, timeout=120
    )
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "recap: error: sweep.yaml: malformed YAML at line 10, column 1: expected ',' or ']', but got '<stream end>'"
    ]
    assert r.stdout == ""
    assert not (tmp_path / "out").exists()
