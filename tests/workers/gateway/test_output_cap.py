"""The output cap end to end: the method's max_tokens reaches the provider unless the model's
own params cap it, and a reply the provider cuts (finish_reason ``length``) ends the episode as
``truncated`` — through litellm's real HTTP client against the fake server, never as a JSON
failure."""

from __future__ import annotations

from recap.baselines import CoTAgent, PlanConfig
from recap.blocksworld import BENCHMARK
from workers.envs.registry import get_benchmark
from workers.llm.direct import LiteLLMClient
from workers.llm.providers import DEFAULT_MAX_TOKENS, DeploymentConfig


def test_generation_params_send_the_method_cap_unless_the_model_caps_it():
    free = DeploymentConfig(model="openai/x")
    assert free.generation_params(0.5, 3072, True)["max_tokens"] == 3072
    assert free.generation_params(0.5, None, True)["max_tokens"] == DEFAULT_MAX_TOKENS
    capped = DeploymentConfig(model="openai/x", params={"max_tokens": 512})
    assert capped.generation_params(0.5, 3072, True)["max_tokens"] == 512
    assert capped.generation_params(0.5, 256, True)["max_tokens"] == 256
    assert capped.generation_params(0.5, None, True)["max_tokens"] == 512


def test_no_method_cap_sends_the_models_whole_output():
    """The paper/released profiles send max_tokens None (issue 25 item 9): the request carries the
    model's own maximum, so no reply the provider would finish is cut by us."""
    from recap.methods import make_agent
    from workers.llm.providers import model_max_output_tokens

    for method in ("recap", "react", "act", "cot", "standard", "adapt"):
        for profile in ("paper", "released"):
            assert make_agent(method, profile=profile, benchmark=get_benchmark("robotouille")).config.max_tokens is None
    assert make_agent("recap").config.max_tokens == 3072  # no profile: the measured cap, unchanged
    gpt4o = DeploymentConfig(model="openai/gpt-4o-2024-08-06")
    assert gpt4o.generation_params(0.5, None, True)["max_tokens"] == model_max_output_tokens("openai/gpt-4o-2024-08-06") == 16384
    assert DeploymentConfig(model="deepseek/deepseek-chat").generation_params(None, None, True)["max_tokens"] == 8192
    assert model_max_output_tokens("openai/x") is None  # unknown: DEFAULT_MAX_TOKENS above
    assert DeploymentConfig(model="offline/expert").generation_params(None, None, True)["max_tokens"] == DEFAULT_MAX_TOKENS


def test_a_plan_cut_by_the_provider_ends_as_truncated(fake_server):
    # a long CoT plan: 400 characters = 100 estimated tokens, cut at the method's cap of 40
    plan = '{"think": "' + "step " * 70 + '", "actions": ["pick up A"]}'
    server = fake_server(reply=plan, keep_bodies=True)
    client = LiteLLMClient(DeploymentConfig(model="openai/fake-gpt", api_base=server.base_url, max_attempts=1))
    env = BENCHMARK.make("blocksworld/3@1")
    result = CoTAgent(PlanConfig(max_tokens=40)).run(env, client, episode_id="ep", demonstration=False)
    assert result.end_reason == "truncated" and result.llm_calls == 1 and result.json_repairs == 0
    assert result.error == "reply cut at the output cap (40 tokens, max_tokens 40)"
    assert server.bodies[0]["max_tokens"] == 40
    # the same reply under a cap it fits in is parsed as usual
    server2 = fake_server(reply=plan)
    client2 = LiteLLMClient(DeploymentConfig(model="openai/fake-gpt", api_base=server2.base_url, max_attempts=1))
    result = CoTAgent(PlanConfig()).run(BENCHMARK.make("blocksworld/3@1"), client2, episode_id="ep2", demonstration=False)
    assert result.end_reason != "truncated" and result.llm_calls == 1
