"""FEVER's protocol for the methods: profiles, verdict-only CoT/Standard, the shared demonstration,
the offline expert's play, and the end reasons a wrong verdict and a Wikipedia failure give."""

from __future__ import annotations

import pytest

import recap.methods as methods
from recap.env import agent_action
from recap.runtime import EnvDriver, EpisodeEnd
from schemas.kinds import END_REASONS
from schemas.labels import infra_failure
from workers.envs.fever import BENCHMARK, FeverEnvironment
from workers.envs.fever.demo import SCRIPT, demonstration_for
from workers.envs.fever.rules import rules_text
from workers.envs.fever.standin import StandIn
from workers.envs.registry import make_env


def agent(method: str, profile: str = "paper"):
    return methods.make_agent(method, profile=profile, benchmark=BENCHMARK)


def test_released_profile_settings_follow_the_release_and_paper_keeps_its_own():
    recap = agent("recap", "released").config
    assert (recap.window, recap.window_counts_pins, recap.context_drop, recap.reminder_period, recap.temperature) == (
        32,
        True,
        32,
        10,  # fever-recap/MATRIX/MATRIX/chatbot.py:352-360 re-sends the rules every 10th call
        None,
    )
    assert (recap.reminder_on, recap.pin_task, recap.think, recap.final_answer, recap.safety_steps) == (
        "nth_call",
        False,
        "many",
        True,
        50,
    )
    assert BENCHMARK.options_for_agent("recap", recap) == {"max_steps": 50}
    react = agent("react", "released").config
    assert (react.history, react.temperature, react.reply_format) == ("all", None, "json")
    act = agent("act", "released").config
    assert (act.history, act.temperature, act.reply_format) == ("all", None, "json")
    cot = agent("cot", "released").config
    assert (cot.temperature, cot.reply_format) == (None, "json")
    paper = agent("recap", "paper").config
    assert (paper.temperature, paper.window, paper.reminder_period) == (0.5, 128, 10)


def test_cot_and_standard_give_only_the_verdict():
    for method in ("cot", "standard"):
        a = agent(method)
        assert BENCHMARK.options_for_agent(a.style, a.config) == {"verdict_only": True}
    for method in ("recap", "react", "act"):
        a = agent(method)
        assert BENCHMARK.options_for_agent(a.style, a.config) == {}
    assert BENCHMARK.refuses_method("adapt") is not None and BENCHMARK.refuses_method("recap") is None
    assert "search[entity]" in rules_text(10) and "At most 10 actions" in rules_text(10)
    assert "search[" not in rules_text(10, verdict_only=True)
    assert rules_text(10, verdict_only=True).endswith("finish[SUPPORTS], finish[REFUTES] or finish[NOT ENOUGH INFO].")


@pytest.mark.parametrize("method", ["recap", "react", "act", "cot", "standard"])
@pytest.mark.parametrize("profile", ["paper", "released"])
def test_every_method_renders_the_shared_demonstration(method, profile):
    a = agent(method, profile)
    verdict_only = BENCHMARK.options_for_agent(a.style, a.config).get("verdict_only", False)
    text = a.render_demonstration(demonstration_for(10, verdict_only=verdict_only))
    assert "Claim: Adrienne Bailon is an accountant." in text and "finish[REFUTES]" in text
    assert text.endswith("[End of example: the goal was reached.]")
    # the search's observation is the release's: five sentences of the page, ". "-split
    searched = "Adrienne Eliza Bailon Houghton (born October 24, 1983) is an American singer, actress and television host."
    assert (searched in text) is (not verdict_only)
    assert ("No more results." in text) is (not verdict_only)


def test_demonstration_script_plays_its_own_actions():
    env = demonstration_for(10).make_env()
    env.reset()
    observations = [env.step(a).observation for a in SCRIPT.actions]
    assert observations[1:] == ["No more results.\n", "Episode finished, reward = 1\n"]
    assert observations[0].endswith("She married the musician Israel Houghton in 2016..")


def test_expert_plan_searches_the_first_evidence_page_then_gives_the_label(make):
    env = make(1001)
    env.reset()
    assert env.expert_plan() == ["search[Nikolaj Coster-Waldau]", "finish[SUPPORTS]"]
    env.step("search[Nikolaj Coster-Waldau]")
    assert env.expert_plan() == ["finish[SUPPORTS]"]
    verdict = make(1003, verdict_only=True)
    verdict.reset()
    assert verdict.expert_plan() == ["finish[NOT ENOUGH INFO]"]


def test_a_wrong_verdict_ends_agent_done_and_a_wiki_failure_ends_wiki_error(make, standin: StandIn):
    env = make(1002)
    driver = EnvDriver(env, "e", lambda r: None)
    driver.reset()
    with pytest.raises(EpisodeEnd) as info:
        driver.execute("finish[SUPPORTS]")
    assert (info.value.reason, info.value.detail) == (
        "agent_done",
        "the environment ended the episode after 1 steps without success",
    )
    assert isinstance(env, FeverEnvironment)
    broken = make(1002, wikipedia_url=standin.base_url)
    driver = EnvDriver(broken, "e", lambda r: None)
    driver.reset()
    with pytest.raises(EpisodeEnd) as info:
        driver.execute("search[Gone]")  # 403: refused at once, no retry
    assert info.value.reason == "wiki_error" and info.value.detail.startswith("unavailable: Wikipedia answer for ")
    assert "wiki_error" in END_REASONS
    # a site that failed is retried by resume like infra_error; a snapshot miss is an outcome
    assert infra_failure("wiki_error", info.value.detail) == "wiki_unavailable"
    assert infra_failure("wiki_error", "snapshot_miss: the snapshot holds no answer") is None


def test_the_agent_facing_layer_lower_cases_the_first_letter_and_the_environment_does_not(make):
    # hotpotqa_simulator.py:41 lower-cases action[0] before stepping; the env takes actions as written
    env = make(1001)
    env.reset()
    assert env.step("Search[Nikolaj Coster-Waldau]").observation == "Invalid action: Search[Nikolaj Coster-Waldau]"
    assert agent_action(env, "Search[Nikolaj Coster-Waldau]") == "search[Nikolaj Coster-Waldau]"
    assert agent_action(env, "") == ""
    records: list = []
    driver = EnvDriver(make(1001), "e", records.append)
    driver.reset()
    step = driver.execute("Search[Nikolaj Coster-Waldau]")
    assert step.observation.startswith("Nikolaj William Coster-Waldau")
    assert [r.action for r in records] == ["search[Nikolaj Coster-Waldau]"]
    with pytest.raises(EpisodeEnd) as info:
        driver.execute("Finish[SUPPORTS]")
    assert info.value.reason == "success"


def test_other_environments_get_actions_as_written():
    env = make_env("blocksworld/3@1")
    assert env.action_spelling == "as_written"
    assert agent_action(env, "Pick up the red block") == "Pick up the red block"


def test_the_claims_label_is_the_episodes_task_and_not_in_the_prompt_material(make):
    supports, refutes = make(1001), make(1002)
    assert (supports.task, refutes.task, supports.split) == ("SUPPORTS", "REFUTES", "dev")
    assert supports.rules() == refutes.rules()
    assert repr(supports.demonstration()) == repr(refutes.demonstration()) == "Demonstration(name='fever-156709-cap10')"
    assert refutes.reset().observation == "Claim: Mercury is a city."
