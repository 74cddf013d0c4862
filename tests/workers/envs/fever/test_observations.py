"""Every FEVER observation kind, byte for byte: hard-coded strings, and the release's own code on the same HTML."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.workers.envs.fever.release import ReleaseEnv
from workers.envs.fever import WikiError

ARTICLE_OBS = (
    "Nikolaj William Coster-Waldau (Danish: [ˈnikolaj ˈkʰʌstɐ ˈʋalˀdɑw]; born 27 July 1970) is a Danish actor and "
    "producer.[1] He graduated from the Danish National School of Performing Arts in Copenhagen in 1993, and had his "
    "breakthrough role in Denmark with the film Nightwatch (1994). He played Jaime Lannister in the HBO fantasy drama "
    "series Game of Thrones, for which he received two Primetime Emmy Award nominations.. Coster-Waldau has appeared in "
    "numerous films in his native Denmark and Scandinavia, including Headhunters (2011) and A Thousand Times Good Night "
    "(2013). In the U.S. his debut film role was in the war film Black Hawk Down (2001), playing Medal of Honor "
    "recipient Gary Gordon."
)
SIMILAR = "Could not find Nikolaj. Similar: ['Nikolaj Coster-Waldau', 'Nikolaj Lie Kaas', \"Nikolaj's Church\", 'Nikolaj Znaider', 'Nikolaj Kirk']."
MISSING_TAIL = "does not exist. You can create a draft and submit it for review.. Main pageRandom article. This page was last edited on 1 March 2024, at 10:00 (UTC).."


def missing(name: str) -> str:
    return f'There were no results matching the query.. The page "{name}" {MISSING_TAIL}'


# (claim index in the claims file, claim id, [(action, observation, reward, done)])
SCENARIOS = {
    "page_lookup_finish": (
        0,
        1001,
        [
            ("search[Nikolaj Coster-Waldau]", ARTICLE_OBS, 0, False),
            (
                "lookup[Fox]",
                "(Result 1 / 1) He then played a detective in the short-lived Fox television series New Amsterdam (2008) – and the Fox TV film Virtuality (2009)..",
                0,
                False,
            ),
            ("lookup[Fox]", "No more results.\n", 0, False),
            ("lookup[Fox]", "No more results.\n", 0, False),
            ("lookup[daughters]", "(Result 1 / 1) The couple has two daughters..", 0, False),
            ("finish[SUPPORTS]", "Episode finished, reward = 1\n", 1, True),
        ],
    ),
    "similar_disambiguation_invalid_missing_redirect": (
        1,
        1002,
        [
            ("lookup[Fox]", "No more results.\n", 0, False),
            ("search[Nikolaj]", SIMILAR, 0, False),
            ("search[Mercury]", "Could not find [Mercury]. Similar: ['Mercury (planet)', 'Mercury (element)'].", 0, False),
            ("think[hmm]", "Nice thought.", 0, False),
            ("Search[Mercury]", "Invalid action: Search[Mercury]", 0, False),
            ("  search[Xyzzy qwerty]  ", missing("Xyzzy qwerty"), 0, False),
            ("lookup[draft]", "(Result 1 / 1) You can create a draft and submit it for review..", 0, False),
            ("search[Coster-Waldau]", ARTICLE_OBS, 0, False),
            ("finish[refutes]", "Episode finished, reward = 1\n", 1, True),
        ],
    ),
    "failed_search_keeps_page_url_quirks": (
        2,
        1003,
        [
            ("search[Nikolaj Coster-Waldau]", ARTICLE_OBS, 0, False),
            ("search[Nikolaj]", SIMILAR, 0, False),
            (
                "lookup[Copenhagen]",
                "(Result 1 / 2) Nikolaj William Coster-Waldau (Danish: [ˈnikolaj ˈkʰʌstɐ ˈʋalˀdɑw]; born 27 July 1970) is a Danish actor and producer.[1] He graduated from the Danish National School of Performing Arts in Copenhagen in 1993, and had his breakthrough role in Denmark with the film Nightwatch (1994).",
                0,
                False,
            ),
            ("search[AT&T]", missing("AT"), 0, False),  # the release sends search=AT&T: the server reads "AT"
            ("search[Beyoncé]", missing("Beyoncé"), 0, False),
            ("", "Invalid action: ", 0, False),
            ("finish[NOT ENOUGH INFO.]", "Episode finished, reward = 1\n", 1, True),
        ],
    ),
    "wrong_verdict": (0, 1001, [("finish[REFUTES]", "Episode finished, reward = 0\n", 0, True)]),
    "answer_normalised": (1, 1002, [("finish[  The Refutes!  ]", "Episode finished, reward = 1\n", 1, True)]),
}


def play(env, actions):
    first = env.reset().observation
    out = []
    for action in actions:
        step = env.step(action)
        out.append((step.observation, step.info["reward"], step.done))
    return first, out


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_observations_match_the_recorded_strings(name, make):
    _index, claim_id, script = SCENARIOS[name]
    env = make(claim_id)
    first, out = play(env, [a for a, *_ in script])
    assert (
        first
        == "Claim: "
        + {
            1001: "Nikolaj Coster-Waldau worked with the Fox Broadcasting Company.",
            1002: "Mercury is a city.",
            1003: "Xyzzy qwerty is a word.",
        }[claim_id]
    )
    assert out == [(obs, reward, done) for _a, obs, reward, done in script]
    assert env.steps_taken == len(script)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_observations_match_the_release_code(name, make, standin, claims_dir, tmp_path: Path, monkeypatch):
    index, claim_id, script = SCENARIOS[name]
    actions = [a for a, *_ in script]
    release = ReleaseEnv(tmp_path, standin.base_url, claims_dir / "paper_dev.jsonl", monkeypatch)
    assert play(make(claim_id), actions) == release.play(index, actions)


def test_success_only_with_the_right_verdict(make):
    env = make(1001)
    env.reset()
    step = env.step("finish[SUPPORTS]")
    assert (step.done, step.success, step.info["gt_answer"]) == (True, True, "SUPPORTS")
    env = make(1001)
    env.reset()
    assert env.step("finish[NOT ENOUGH INFO]").success is False


def test_step_cap_ends_the_episode_after_ten_actions(make):
    env = make(1003)
    env.reset()
    steps = [env.step(f"think[{k}]") for k in range(10)]
    assert [s.done for s in steps] == [False] * 9 + [True]
    assert steps[-1].success is False and steps[-1].info["end_reason"] == "step_cap"
    with pytest.raises(Exception, match="the episode is over"):
        env.step("finish[SUPPORTS]")


def test_search_answers_are_recorded_with_their_request_url(make, store, standin):
    env = make(1001)
    env.reset()
    env.step("search[Coster-Waldau]")
    env.step("search[Mercury]")
    urls = [r.url for r in store.records]
    base = standin.base_url
    assert urls == [
        f"{base}/w/index.php?search=Coster-Waldau",
        f"{base}/w/index.php?search=Mercury",
        f"{base}/w/index.php?search=%5BMercury%5D",
    ]
    assert store.records[0].final_url == f"{base}/wiki/Nikolaj_Coster-Waldau"
    assert [r.status for r in store.records] == [200, 200, 200]
    assert all(r.encoding.lower() == "utf-8" for r in store.records)


def test_page_the_release_cannot_clean_is_an_environment_error(make, standin, store):
    env = make(1001)
    env.reset()
    with pytest.raises(
        WikiError,
        match=r"search=Windows\+path cannot be read as the release reads it: text the release cannot clean \(UnicodeDecodeError",
    ) as info:
        env.step("search[Windows path]")
    assert (info.value.kind, info.value.end_reason) == ("unreadable", "wiki_error")


def test_plan_copy_shares_the_source_and_steps_past_the_end(make, standin):
    env = make(1001)
    env.reset()
    env.step("search[Nikolaj Coster-Waldau]")
    sim = env.plan_copy()
    assert sim.step("lookup[daughters]").observation == "(Result 1 / 1) The couple has two daughters.."
    assert sim.step("finish[SUPPORTS]").success is True
    again = sim.step("lookup[Fox]")
    assert (again.observation, again.done, again.success) == ("Episode finished, reward = 1\n", True, True)
    assert env.steps_taken == 1 and env.lookup_keyword is None
