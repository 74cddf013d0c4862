"""Refused before any call, not after (issue 24, class 2): every number of the sweep file has a
declared range that the refusal states, an unknown provider is refused, ``api_key_env`` names a
credential, and ``params.max_tokens`` fits the model (nothing is lowered without a word).

The four cases of the issue go through the real CLI as a process (``python -m pipeline.cli run``
and ``estimate``): exit status 2, one line on stderr, no run folder, and the provider (a fake
server) sees no request.
"""

from __future__ import annotations

import os
import subprocess
import sys
import types
import typing
from pathlib import Path
from typing import Any

import pytest
import yaml
from pydantic import BaseModel

from pipeline.cli import main
from pipeline.errors import SpecError
from pipeline.preflight import check_models
from pipeline.spec import (
    CREDENTIAL_WORDS,
    NUMBER_BOUNDS,
    TIMEOUT_MAX,
    Bounded,
    SweepSpec,
    credential_name,
    number_text,
    parse_spec,
)
from workers.llm.offline.fake_server import FakeServer, FakeServerConfig
from workers.llm.providers import ALLOWED_PARAMS, MAX_TOKENS_CEILING, NUMERIC_PARAMS, DeploymentConfig

REPO = Path(__file__).resolve().parents[3]

BASE: dict[str, Any] = {
    "run": "bounds",
    "output": "/tmp/never-written-bounds",
    "models": [{"model": "offline/expert"}],
    "methods": [{"method": "recap"}],
    "environments": [{"benchmark": "blocksworld", "tasks": ["3"]}],
}


# --------------------------------------------------------------------------------------------
# 1. every number field of the schema has a declared range
# --------------------------------------------------------------------------------------------
def _number_fields(model: type[BaseModel], prefix: str = "") -> dict[str, tuple[type, list[Any]]]:
    """Path -> (int or float, metadata) of every number field of ``model`` and the models under it (lists as
    ``name[]``), found by walking the type annotations: a new number field shows up here."""
    found: dict[str, tuple[type, list[Any]]] = {}

    def walk(tp: Any, path: str, meta: list[Any]) -> None:
        origin = typing.get_origin(tp)
        if origin is typing.Annotated:
            inner, *extra = typing.get_args(tp)
            walk(inner, path, meta + list(extra))
        elif origin in (typing.Union, types.UnionType):
            for arg in typing.get_args(tp):
                walk(arg, path, meta)
        elif origin is list:
            walk(typing.get_args(tp)[0], path + "[]", meta)
        elif origin is dict and typing.get_args(tp)[1] is not typing.Any:
            walk(typing.get_args(tp)[1], path + "{}", meta)  # a typed mapping's values (step_multipliers)
        elif origin is dict or tp in (str, bool, type(None)) or origin is typing.Literal:
            return  # free-form mappings have their own tables (tested below); no numbers otherwise
        elif isinstance(tp, type) and issubclass(tp, BaseModel):
            found.update(_number_fields(tp, path + "."))
        elif tp in (int, float):
            found[path] = (tp, meta)
        else:
            raise AssertionError(f"{path}: a field type this test does not know ({tp!r}): teach it")

    for name, field in model.model_fields.items():
        walk(field.annotation, prefix + name, list(field.metadata))
    return found


def test_every_number_field_of_the_sweep_file_has_a_declared_range():
    fields = _number_fields(SweepSpec)
    assert len(fields) >= 20  # the walk found the fields (rpm, window_s, prices.input, seeds[] ...)
    unbounded = [p for p, (_, meta) in fields.items() if not any(isinstance(m, Bounded) and m.path == p for m in meta)]
    assert unbounded == []
    assert set(NUMBER_BOUNDS) == set(fields)  # no stale entry in the table either
    for path, b in NUMBER_BOUNDS.items():
        assert b.lo < b.hi and b.hi < float("inf"), path


def _set(data: dict[str, Any], path: str, value: Any) -> str:
    """``data`` with ``value`` at the table path (``models[].prices.input``); returns the path
    the refusal names (``models[0].prices.input``)."""
    parts = path.replace("[]", ".[]").split(".")
    node: Any = data
    shown = ""
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        if part == "[]":
            shown += "[0]"
            if last:
                node[:] = [value]
                return shown
            if not node:
                node.append({})
            node = node[0]
            continue
        if part.endswith("{}"):  # a typed mapping: one entry (its key names it in the refusal)
            key = "blocksworld/3"
            node[part[:-2]] = {key: value}
            return shown + "." + part[:-2] + "." + key
        shown += ("." if shown else "") + part
        if last:
            node[part] = value
        else:
            if part == "prices" and parts[i + 1] in ("gpu_hour", "replica_hour"):
                node.setdefault("serve", {})  # an hourly price is a served model's
                node.setdefault(part, {})
            elif part == "prices":
                node.setdefault(part, {"input": 1, "output": 1})
            node = node.setdefault(part, [] if parts[i + 1] == "[]" else {})
    return shown


def _outside(lo: float, hi: float, integer: bool) -> tuple[Any, Any]:
    if integer:
        return int(lo) - 1, int(hi) + 1
    return (lo / 10 if lo > 0 else lo - 1), hi * 10


#: the integer fields (their out-of-range probes are integers too)
INTEGER_FIELDS = {p for p, (tp, _) in _number_fields(SweepSpec).items() if tp is int}


@pytest.mark.parametrize("path", sorted(NUMBER_BOUNDS))
def test_each_range_refuses_just_outside_and_takes_its_ends(path):
    b = NUMBER_BOUNDS[path]
    integer = path in INTEGER_FIELDS
    for value in _outside(b.lo, b.hi, integer):
        data = yaml.safe_load(yaml.safe_dump(BASE))
        shown = _set(data, path, value)
        with pytest.raises(SpecError) as info:
            parse_spec(yaml.safe_dump(data), "sweep.yaml")
        assert str(info.value) == f"sweep.yaml: {shown}: {number_text(value)} is out of range {b.text()}"
    for value in (b.lo, b.hi):
        data = yaml.safe_load(yaml.safe_dump(BASE))
        _set(data, path, int(value) if integer else float(value))
        parse_spec(yaml.safe_dump(data), "sweep.yaml")


def test_the_attempt_timeout_fits_the_gateway_total_so_it_is_never_cut_silently():
    assert TIMEOUT_MAX == DeploymentConfig.model_fields["total_timeout_s"].default


def test_every_numeric_generation_param_has_a_finite_range():
    numeric = {"temperature", "top_p", "max_tokens", "n", "seed", "presence_penalty", "frequency_penalty"}
    assert numeric <= ALLOWED_PARAMS and set(NUMERIC_PARAMS) == numeric
    for name, (_, lo, hi) in NUMERIC_PARAMS.items():
        assert lo <= hi < float("inf"), name
    assert NUMERIC_PARAMS["max_tokens"] == (True, 1, MAX_TOKENS_CEILING)


@pytest.mark.parametrize(
    "params, message",
    [
        ({"max_tokens": 10**12}, "params: max_tokens 1000000000000 is out of range [1, 262144]"),
        ({"max_tokens": 0}, "params: max_tokens 0 is out of range [1, 262144]"),
        ({"temperature": 2.5}, "params: temperature 2.5 is out of range [0, 2]"),
        ({"top_p": -0.1}, "params: top_p -0.1 is out of range [0, 1]"),
        ({"seed": -1}, "params: seed -1 is out of range [0, 9223372036854775807]"),
        ({"presence_penalty": 3}, "params: presence_penalty 3 is out of range [-2, 2]"),
        ({"max_tokens": 1.5}, "params: max_tokens must be an integer in [1, 262144], got 1.5"),
        ({"logit_bias": {"50256": -101}}, "params: logit_bias entry '50256': -101 is out of range [-100, 100]"),
    ],
)
def test_generation_params_out_of_range_name_the_range(params, message):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["models"][0]["params"] = params
    with pytest.raises(SpecError) as info:
        check_models(parse_spec(yaml.safe_dump(data), "sweep.yaml"))
    assert str(info.value) == f"models[0] (offline/expert): {message}"


@pytest.mark.parametrize(
    "options, message",
    [
        ({"noise_seed": -1}, "noise_seed -1 is out of range [0, 9223372036854775807]"),
        ({"seed": -1}, "seed -1 is out of range [0, 9223372036854775807]"),  # the old name, as the file gives it
        ({"seed": 1, "noise_seed": 1}, "give noise_seed or its old name seed, not both"),
        ({"chunk_size": 0}, "chunk_size 0 is out of range [1, 1000]"),
        ({"invalid_action_rate": 1.5}, "invalid_action_rate 1.5 is out of range [0, 1]"),
    ],
)
def test_test_double_options_out_of_range_name_the_range(options, message):
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["models"][0]["options"] = options
    with pytest.raises(SpecError) as info:
        check_models(parse_spec(yaml.safe_dump(data), "sweep.yaml"))
    assert str(info.value) == f"models[0] (offline/expert): {message}"


# --------------------------------------------------------------------------------------------
# 2. providers, key variables and output limits (pipeline.preflight.check_models)
# --------------------------------------------------------------------------------------------
def _models_problem(**entry: Any) -> str | None:
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["models"] = [entry]
    try:
        check_models(parse_spec(yaml.safe_dump(data), "sweep.yaml"))
    except SpecError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize(
    "entry",
    [
        {"model": "gpt-4o"},
        {"model": "gpt-4o-mini", "params": {"max_tokens": 16384}},
        {"model": "openai/anything-at-all", "api_base": "http://127.0.0.1:9/v1"},
        {"model": "openai/SmolLM2-135M-Instruct", "params": {"max_tokens": 262144}},
        {"model": "together_ai/Qwen/Qwen2.5-72B-Instruct-Turbo"},
        {"model": "anthropic/claude-sonnet-4-5"},
        {"model": "offline/random"},
    ],
)
def test_models_litellm_can_route_pass(entry):
    assert _models_problem(**entry) is None


@pytest.mark.parametrize(
    "entry, message",
    [
        (
            {"model": "OpenAI/gpt-4o"},
            "models[0] (OpenAI/gpt-4o): unknown provider 'OpenAI' in 'OpenAI/gpt-4o' (nearest known: openai, openai_like, "
            "edenai); an OpenAI-compatible server at api_base is openai/gpt-4o",
        ),
        (
            {"model": "togetherai/deepseek-ai/DeepSeek-V3"},
            "models[0] (togetherai/deepseek-ai/DeepSeek-V3): unknown provider 'togetherai' in "
            "'togetherai/deepseek-ai/DeepSeek-V3' (nearest known: together_ai, ",
        ),
        (
            {"model": "zzz", "api_base": "http://127.0.0.1:9/v1"},
            "models[0] (zzz): litellm does not know the model 'zzz' and it names no provider; write provider/model "
            "(openai/zzz for an OpenAI-compatible server at api_base)",
        ),
        (
            {"model": "offline/tiny"},
            "models[0] (offline/tiny): unknown test double 'offline/tiny'; known: offline/expert, offline/random, offline/replay",
        ),
        (
            {"model": "gpt-4o-mini", "params": {"max_tokens": 16385}},
            "models[0] (gpt-4o-mini): params.max_tokens 16385 is above the model's output limit 16384 "
            "(litellm's max_output_tokens for gpt-4o-mini); use at most 16384",
        ),
    ],
)
def test_models_no_call_could_reach_are_refused(entry, message):
    problem = _models_problem(**entry)
    assert problem is not None and problem.startswith(message), problem


@pytest.mark.parametrize("name", ["OPENAI_API_KEY", "HF_TOKEN", "WATSONX_APIKEY", "MY_SECRET", "DB_PASSWORD", "key", "token"])
def test_credential_names(name):
    assert credential_name(name)


@pytest.mark.parametrize("name", ["HOME", "PATH", "AZURE_API_BASE", "MONKEY", "KEYS", "OPENAI_API_KEY_FILE", "USER"])
def test_names_that_are_not_credentials(name):
    assert not credential_name(name)
    message = _models_problem(model="openai/gpt-4o", api_key_env=name)
    assert message == (
        f"sweep.yaml: models[0].api_key_env: {name} does not name a credential (a variable ending in "
        f"{', '.join('_' + w for w in CREDENTIAL_WORDS)}) and its value would be sent to the provider as the API key; "
        "if it does hold the key, add api_key_env_is_credential: true"
    )


def test_the_override_vouches_for_one_variable_and_needs_one():
    assert _models_problem(model="openai/gpt-4o", api_key_env="HOME", api_key_env_is_credential=True) is None
    assert _models_problem(model="openai/gpt-4o", api_key_env_is_credential=True) == (
        "sweep.yaml: models[0]: api_key_env_is_credential: true needs api_key_env (the variable it vouches for)"
    )


@pytest.mark.parametrize(
    "model", ["openai/gpt-4o", "anthropic/claude-sonnet-4-5", "together_ai/x", "deepseek/deepseek-chat", "gemini/x", "groq/x"]
)
def test_the_providers_own_key_variables_are_credentials(model):
    from pipeline.preflight import key_variables
    from pipeline.spec import ModelSpec

    names = key_variables(ModelSpec(model=model))
    assert names and all(credential_name(n) for n in names), names


# --------------------------------------------------------------------------------------------
# 3. the four cases of the issue through the CLI as a process: refused before any call
# --------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def server():
    s = FakeServer(FakeServerConfig())
    s.start_in_thread()
    yield s
    s.stop_thread()


ISSUE_CASES = [
    (
        "unknown provider prefix",
        "  - model: nosuchprovider/zzz\n    api_base: {url}\n    api_key_env: RECAP_BOUNDS_KEY\n",
        "models[0] (nosuchprovider/zzz): unknown provider 'nosuchprovider' in 'nosuchprovider/zzz' (nearest known: ",
    ),
    (
        "meaningless quota window",
        "  - model: openai/fake-gpt\n    api_base: {url}\n    api_key_env: RECAP_BOUNDS_KEY\n    rpm: 60\n    window_s: 1.0e-300\n",
        "models[0].window_s: 1e-300 is out of range [0.1, 86400]",
    ),
    (
        "a variable that is not a credential",
        "  - model: openai/fake-gpt\n    api_base: {url}\n    api_key_env: HOME\n",
        "models[0].api_key_env: HOME does not name a credential",
    ),
    (
        "max_tokens beyond any model",
        "  - model: openai/fake-gpt\n    api_base: {url}\n    api_key_env: RECAP_BOUNDS_KEY\n    params: {{max_tokens: 1000000000000}}\n",
        "models[0] (openai/fake-gpt): params: max_tokens 1000000000000 is out of range [1, 262144]",
    ),
]


@pytest.mark.parametrize("command", ["run", "estimate"])
@pytest.mark.parametrize("model, expect", [c[1:] for c in ISSUE_CASES], ids=[c[0] for c in ISSUE_CASES])
def test_the_issue_cases_are_refused_by_the_cli_before_any_call(tmp_path, server, command, model, expect):
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    text = (
        f"run: bounds\noutput: {out}\nmodels:\n{model.format(url=server.base_url)}"
        'methods: [{method: react}]\nenvironments: [{benchmark: blocksworld, tasks: ["3"]}]\n'
    )
    spec.write_text(text)
    env = dict(os.environ, PYTHONPATH=str(REPO), RECAP_BOUNDS_KEY="sk-bounds-test", LITELLM_LOCAL_MODEL_COST_MAP="True")
    argv = [sys.executable, "-m", "pipeline.cli", command, str(spec)] + (["--progress", "off"] if command == "run" else [])
    before = len(server.log)
    r = subprocess.run(argv, capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1 and lines[0].startswith(f"recap: error: sweep.yaml: {expect}"), lines
    assert r.stdout == ""
    assert not out.exists()
    assert len(server.log) == before  # the provider saw nothing


def test_a_refused_model_in_process_writes_nothing(tmp_path, capsys):
    """The in-process entry point too (what the other hardening tests use)."""
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["output"] = str(out)
    data["models"] = [{"model": "nosuchprovider/zzz", "api_base": "http://127.0.0.1:9/v1", "api_key_env": "RECAP_X_KEY"}]
    spec.write_text(yaml.safe_dump(data))
    assert main(["run", str(spec), "--progress", "off"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "unknown provider 'nosuchprovider'" in err[0]
    assert not out.exists()


# --------------------------------------------------------------------------------------------
# 4. method settings (free-form in the file, bounded by the method's config)
# --------------------------------------------------------------------------------------------
def test_every_number_setting_of_every_built_in_method_has_a_range():
    import dataclasses

    from recap.config import SETTING_BOUNDS
    from recap.methods import METHODS

    missing = []
    for method, (_, config_cls) in METHODS.items():
        hints = typing.get_type_hints(config_cls)
        for f in dataclasses.fields(config_cls):
            kinds = set(typing.get_args(hints[f.name])) | {hints[f.name]}
            if kinds & {int, float} and f.name not in SETTING_BOUNDS:
                missing.append(f"{method}.{f.name}")
    assert missing == []
    for name, (lo, hi) in SETTING_BOUNDS.items():
        assert lo < hi < float("inf"), name


@pytest.mark.parametrize(
    "method, settings, message",
    [
        ("recap", {"window": 10**9}, "window 1000000000 is out of range [2, 100000]"),
        ("recap", {"window": 64.5}, "window must be an integer in [2, 100000], got 64.5"),
        ("recap", {"max_tokens": 10**12}, "max_tokens 1000000000000 is out of range [1, 262144]"),
        ("react", {"max_episode_cost_usd": 1e-300}, "max_episode_cost_usd 1e-300 is out of range [1e-06, 1000000]"),
        ("adapt", {"executor_steps": 10**7}, "executor_steps 10000000 is out of range [1, 100000]"),
    ],
)
def test_method_settings_out_of_range_are_refused_by_the_cli(tmp_path, capsys, method, settings, message):
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["output"] = str(out)
    data["methods"] = [{"method": method, "settings": settings}]
    spec.write_text(yaml.safe_dump(data))
    assert main(["estimate", str(spec)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"recap: error: sweep.yaml: methods[0] ({method}): {message}"]
    assert not out.exists()


def test_a_method_output_cap_above_the_model_limit_is_refused_unless_the_model_caps_it(tmp_path, capsys):
    """ReCAP asks for 3072 output tokens; a model whose output limit is 2048 would refuse every
    call unless its own params.max_tokens bounds the requests."""
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    data = yaml.safe_load(yaml.safe_dump(BASE))
    data["output"] = str(out)
    data["methods"] = [{"method": "react"}, {"method": "recap"}]
    data["models"] = [{"model": "azure_ai/Meta-Llama-3-70B-Instruct", "label": "llama"}]
    spec.write_text(yaml.safe_dump(data))
    assert main(["estimate", str(spec)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "recap: error: sweep.yaml: models[0] (llama): methods[1] (recap) asks for max_tokens 3072 but the model's output "
        "limit is 2048 (litellm's max_output_tokens); give the model params: {max_tokens: 2048}"
    ]
    data["models"][0]["params"] = {"max_tokens": 2048}
    spec.write_text(yaml.safe_dump(data))
    assert main(["estimate", str(spec)]) == 0
    assert not out.exists()
