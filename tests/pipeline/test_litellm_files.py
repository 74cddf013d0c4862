"""pipeline.litellm_files answers what litellm answers, and a refused sweep file never imports litellm.

The file readers are compared with the imported litellm (the provider enum, the JSON providers,
the endpoint hosts), and :func:`surely_unroutable` with ``litellm.get_llm_provider`` over a grid
of model strings and ``api_base`` values: it may say "ask litellm" where litellm routes or
refuses, but never "unroutable" where litellm routes. A ``recap run``/``recap estimate`` process
refusing the issue's bad model entries is checked not to have imported litellm or Ray.
"""

from __future__ import annotations

import itertools
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline import litellm_files
from pipeline.preflight import provider_problem
from pipeline.spec import ModelSpec
from workers.llm.litellm_import import import_litellm

REPO = Path(__file__).resolve().parents[2]


def test_the_provider_names_are_litellms_provider_list():
    litellm = import_litellm()
    # less the custom providers registered in this process (the offline test doubles, once a test
    # of this process has called through them): litellm appends those to its list at run time
    custom = {entry["provider"] for entry in litellm.custom_provider_map}
    assert litellm_files.provider_names() == {str(getattr(p, "value", p)) for p in litellm.provider_list} - custom


def test_the_json_providers_and_endpoint_hosts_are_litellms():
    from litellm.llms.openai_like.json_loader import JSONProviderRegistry

    litellm = import_litellm()
    JSONProviderRegistry.load()
    assert litellm_files.json_provider_names() == set(JSONProviderRegistry._providers)
    assert litellm_files.endpoint_hosts() == {litellm_files._host(e) for e in litellm.openai_compatible_endpoints}


MODELS = [
    "nosuchprovider/zzz",
    "bedrockz/anthropic.claude-3",
    "meta-llama/Llama-3-8b",
    "Qwen/Qwen2.5-7B",
    "foo/gpt-4o",
    "x/claude-3-opus",
    "nvidia/x",
    "anthropic.claude-3/x",
    "openai/fake-gpt",
    "together_ai/x",
    "gpt-4o",
    "zzz",
    "nosuch/ft:gpt-4o",
]
BASES = [None, "http://127.0.0.1:9/v1", "https://api.groq.com/openai/v1", "https://api.together.xyz/v1", "http://localhost:8000"]


def test_surely_unroutable_never_refuses_what_litellm_routes():
    litellm = import_litellm()
    said_unroutable = 0
    for model, base in itertools.product(MODELS, BASES):
        if not litellm_files.surely_unroutable(model, base):
            continue
        said_unroutable += 1
        with pytest.raises(Exception):  # noqa: B017  litellm's refusal is a BadRequestError or a bare Exception
            litellm.get_llm_provider(model, api_base=base)
    assert said_unroutable >= 10  # the common refusals are decided from the files (nosuchprovider/zzz at a local server)
    assert litellm_files.surely_unroutable("nosuchprovider/zzz", "http://127.0.0.1:9/v1")
    assert not litellm_files.surely_unroutable("nosuchprovider/zzz", "https://api.groq.com/openai/v1")  # litellm routes it
    assert not litellm_files.surely_unroutable("openai/fake-gpt", None)  # a known provider: not "unroutable"


@pytest.mark.parametrize("model, base", list(itertools.product(MODELS, BASES[:3])))
def test_provider_problem_is_the_same_with_and_without_the_files(monkeypatch, model, base):
    """The message (or None) from the files is the one litellm's own answers give."""
    m = ModelSpec(model=model, api_base=base)
    fast = provider_problem(m)
    monkeypatch.setattr("pipeline.preflight.provider_names", lambda: None)  # the files unreadable: litellm only
    assert provider_problem(m) == fast


_PROBE = """
import json, sys
from pipeline.cli import main
codes = [main([cmd, path] + (["--progress", "off"] if cmd == "run" else [])) for path in sys.argv[1:] for cmd in ("run", "estimate")]
print(json.dumps({"codes": codes, "heavy": sorted(m for m in ("litellm", "ray", "duckdb") if m in sys.modules)}))
"""

BAD_MODELS = {
    "unknown provider": "  - model: nosuchprovider/zzz\n    api_base: http://127.0.0.1:9/v1\n    api_key_env: RECAP_NOIMPORT_KEY\n",
    "max_tokens": "  - model: openai/fake-gpt\n    api_base: http://127.0.0.1:9/v1\n    api_key_env: RECAP_NOIMPORT_KEY\n"
    "    params: {max_tokens: 1000000000000}\n",
    "not a credential": "  - model: openai/fake-gpt\n    api_base: http://127.0.0.1:9/v1\n    api_key_env: HOME\n",
}


def test_a_refused_sweep_file_imports_neither_litellm_nor_ray_nor_duckdb(tmp_path):
    """The refusals of the issue's bad model entries, by run and estimate in one fresh process:
    each exits 2 and none of them loaded litellm (seconds of CPU), Ray or DuckDB."""
    paths = []
    for i, models in enumerate(BAD_MODELS.values()):
        p = tmp_path / f"sweep{i}.yaml"
        p.write_text(
            f"run: noimport\noutput: {tmp_path / 'out'}\nmodels:\n{models}"
            'methods: [{method: react}]\nenvironments: [{benchmark: blocksworld, tasks: ["3"]}]\n'
        )
        paths.append(str(p))
    env = dict(os.environ, PYTHONPATH=str(REPO), RECAP_NOIMPORT_KEY="sk-test", LITELLM_LOCAL_MODEL_COST_MAP="True")
    r = subprocess.run([sys.executable, "-c", _PROBE, *paths], capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    assert out == {"codes": [2] * (2 * len(paths)), "heavy": []}, r.stderr
    assert len(r.stderr.strip().splitlines()) == 2 * len(paths)  # one line per refusal
    assert not (tmp_path / "out").exists()
