"""ReCAP on FEVER under ``profile: released``: the released loop's rules (fever-recap/MATRIX/MATRIX/
chatbot.py, hotpotqa/hotpotqa_simulator.py), each shown by the exact messages a scripted model
receives in one episode (workers/envs/fever/protocol.py RECAP_RELEASED says which line each follows)."""

from __future__ import annotations

import json
from typing import Any

import recap.methods as methods
from recap import recap_prompts as P
from recap.scripted import ScriptedClient
from schemas.records import MessageRecord, StepRecord
from workers.envs.fever import BENCHMARK, FeverEnvironment
from workers.envs.fever.claims import Claim
from workers.envs.fever.standin import page

CLAIM = Claim(0, 7, "Mercury is a planet.", "SUPPORTS")
#: an article whose text holds the two characters backslash-n (the HTML's ``\\n`` is undone once by
#: the release's clean_str, wikienv.py:10-11, leaving one backslash before the n)
MERCURY = page(
    "Mercury (planet)",
    "<p>Mercury is the first planet from the Sun.\\\\n It is the smallest planet in the Solar System.</p>",
)
#: how the observation of a search begins, as the environment gives it (backslash-n included)
SEARCHED = "Mercury is the first planet from the Sun.\\n It is the smallest planet in the Solar System.. Main page"


class OnePage:
    """A Wikipedia source answering every search with the Mercury article."""

    def fetch(self, url: str) -> str:
        return MERCURY


def reply(think: str, *subtasks: str) -> dict[str, Any]:
    return {"think": think, "subtasks": list(subtasks)}


class Run:
    def __init__(self, replies: list[Any], demonstration: str | bool = "DEMO", **settings: Any) -> None:
        agent = methods.make_agent("recap", profile="released", benchmark=BENCHMARK, **settings)
        options = BENCHMARK.options_for_agent(agent.style, agent.config)
        self.env = FeverEnvironment(CLAIM, OnePage(), wikipedia_url="http://wiki.test", max_steps=options["max_steps"])
        self.client = ScriptedClient(replies)
        self.records: list[Any] = []
        self.result = agent.run(self.env, self.client, episode_id="ep", emit=self.records.append, demonstration=demonstration)
        self.rules = self.env.rules()

    def sent(self, call: int) -> list[tuple[str, str]]:
        """The (role, content) messages of call number ``call`` (1-based)."""
        return [(m.role, m.content) for m in self.client.requests[call - 1].messages]

    def prompt(self, call: int) -> str:
        role, content = self.sent(call)[-1]
        assert role == "user"
        return content

    def steps(self) -> list[tuple[str, bool, int]]:
        return [(r.action, r.valid, r.env_step) for r in self.records if isinstance(r, StepRecord)]

    def messages(self) -> list[MessageRecord]:
        return [r for r in self.records if isinstance(r, MessageRecord)]


def task_prompt(rules: str) -> str:
    return P.task_prompt(rules=rules, observation="Claim: Mercury is a planet.", goal=CLAIM.claim, with_think=True, preamble=True)


def test_a_reply_not_matching_the_action_pattern_gets_the_fail_prompt_and_uses_no_step():
    """chatbot.py:308-312 and 412-423: 'search Mercury' is no action; the root gets the fail prompt
    with its whole list, and the environment never sees it (before: it was stepped as an invalid action)."""
    run = Run(
        [
            reply("t0", "find Mercury", "decide"),
            reply("t1", "search Mercury"),
            reply("t2", "Search[Mercury]"),
            reply("t3", "Search[Mercury]"),
            reply("t4"),
            reply("t5", "Finish[SUPPORTS]"),
        ]
    )
    fail = P.return_prompt(
        outcome="fail",
        child_task="find Mercury",
        parent_task=CLAIM.claim,
        thinks=["t0"],
        subtasks=["find Mercury", "decide"],
        observation="Claim: Mercury is a planet.",
        think_mode="many",
        name_only=False,
        failed_action="search Mercury",
        hints=run.env.failure_hints(),
    )[1]
    assert run.prompt(3) == fail
    assert run.steps() == [("search Mercury", False, 0), ("search[Mercury]", True, 1), ("finish[SUPPORTS]", True, 2)]
    assert run.env.steps_taken == 2 and run.result.steps == 2 and run.result.end_reason == "success"


def test_the_root_list_emptying_asks_for_the_final_answer_and_sends_its_first_subtask():
    """chatbot.py:427-429 leaves the loop when the root's list is empty, :470-478 asks for the answer
    and yields its first subtask (before: the episode ended as agent_done with no verdict)."""
    replies = [reply("t0", "Search[Mercury]", "decide"), reply("t1", "Search[Mercury]"), reply("t2")]
    run = Run([*replies, reply("done", "Finish[SUPPORTS]")])
    assert run.prompt(4) == P.final_answer_prompt()
    assert [m.kind for m in run.messages()][-2:] == ["final_answer", "reply"]
    assert run.steps()[-1] == ("finish[SUPPORTS]", True, 2) and run.result.end_reason == "success"
    # an answer that does not end the episode is stepped as it is, then finish[] (hotpotqa_simulator.py:47-49)
    run = Run([*replies, reply("done", "SUPPORTS")])
    assert run.steps()[1:] == [("sUPPORTS", True, 2), ("finish[]", True, 3)]
    assert run.result.end_reason == "agent_done" and not run.result.success


def _failing_rounds(n: int) -> list[dict[str, Any]]:
    """Replies that keep the root failing a child (two calls a round, no step)."""
    out: list[dict[str, Any]] = []
    for i in range(n):
        out += [reply(f"r{i}", "find Mercury", "decide"), reply(f"c{i}", "look Mercury up")]
    return out


def test_the_rules_go_before_the_prompt_of_every_tenth_call():
    """chatbot.py:350-360: invoke_cnt counts every call of the loop and calls 10, 20 carry the rules
    (before: the profile sent no reminder)."""
    run = Run([*_failing_rounds(11), reply("end"), reply("a", "Finish[SUPPORTS]")])
    assert len(run.client.requests) == 24
    reminded = [n for n in range(1, 25) if run.prompt(n).startswith(P.reminder(run.rules) + "\n\n")]
    assert reminded == [10, 20]
    assert run.prompt(10) == run.prompt(20) == P.reminder(run.rules) + "\n\n" + P.descend_prompt("find Mercury")


def test_past_32_messages_the_task_prompt_and_its_reply_go_first_and_the_demonstration_stays():
    """chatbot.py:42-44: past 32 messages history[1:3] is deleted before the prompt goes in;
    history[0] is the demonstration (:76, 330), [1] the task prompt (before: the task prompt was pinned)."""
    run = Run([*_failing_rounds(9), reply("end"), reply("a", "Finish[SUPPORTS]")])
    call16, call17, call18 = run.sent(16), run.sent(17), run.sent(18)
    assert len(call16) == 32 and call16[:2] == [("user", "DEMO"), ("user", task_prompt(run.rules))]
    assert call17[0] == ("user", "DEMO") and call17[1:] == call16[3:] + [call17[-2], call17[-1]]
    assert len(call17) == 32 and len(call18) == 32 and call18[1:] == call17[3:] + call18[-2:]
    assert call17[1] == ("user", run.sent(2)[-1][1])  # the second call's prompt now opens the window


def test_every_thought_of_the_node_comes_back_numbered():
    """chatbot.py:122-126: get_latest_think joins all of the node's thoughts, numbered from 1
    (before: the latest only)."""
    run = Run(
        [
            reply("first", "Search[Mercury]", "decide"),
            reply("c", "Search[Mercury]"),
            reply("second", "Lookup[Sun]", "decide"),
            reply("c", "Lookup[smallest]"),
            reply("third"),
            reply("a", "Finish[SUPPORTS]"),
        ]
    )
    assert "Your earlier reasoning for this task, oldest first:\n1. first\n2. second\n\nYour remaining" in run.prompt(5)
    assert "Your earlier reasoning for this task, oldest first:\n1. first\n\nYour remaining" in run.prompt(3)


def test_backslash_n_is_deleted_from_the_observation_the_prompt_shows():
    """hotpotqa_simulator.py:42: obs.replace('\\\\n', ''); the step row keeps the environment's text."""
    run = Run(
        [reply("t0", "Search[Mercury]", "decide"), reply("c", "Search[Mercury]"), reply("t1"), reply("a", "Finish[SUPPORTS]")]
    )
    seen = [r.observation for r in run.records if isinstance(r, StepRecord)][0]
    shown = seen.replace("\\n", "")
    assert seen.startswith(SEARCHED) and "\\n" not in shown
    assert (
        run.prompt(3)
        == P.return_prompt(
            outcome="leaf",
            child_task="Search[Mercury]",
            parent_task=CLAIM.claim,
            thinks=["t0"],
            subtasks=["decide"],
            observation=shown,
            think_mode="many",
            name_only=False,
        )[1]
    )


def test_the_safety_bound_ends_a_runaway_episode_and_says_so():
    """hotpotqa_simulator.py:22,33: the release counts no steps; our bound (safety_steps, the
    environment's max_steps) ends the episode and the row says it was the bound."""
    run = Run(
        [reply("t", "Search[A]", "Search[B]", "Search[C]"), reply("c", "Search[A]"), reply("t", "Search[B]", "Search[C]")]
        + [reply("c", "Search[B]")],
        safety_steps=2,
    )
    assert run.env.max_steps == 2 and run.result.steps == 2
    assert run.result.end_reason == "step_cap"
    assert run.result.error == "safety bound (2 steps (cap 2); safety_steps 2, the released code has no cap)"
    default = methods.make_agent("recap", profile="released", benchmark=BENCHMARK).config
    assert BENCHMARK.options_for_agent("recap", default) == {"max_steps": 50}


def test_a_one_item_root_list_is_the_roots_own_action_then_the_final_answer():
    """chatbot.py:346, 379-394: the first call is a descend too, so a one-item root list is acted
    on (when it matches) and the loop is left for the final answer (:470-478); one that does not
    match takes no step and the final answer is asked for at once (the release's fail path reads
    the root's parent and the error ends its loop, :414-421, 461-469)."""
    run = Run([reply("t", "Search[Mercury]"), reply("a", "Finish[SUPPORTS]")])
    assert [run.prompt(2)] == [P.final_answer_prompt()] and len(run.client.requests) == 2
    assert run.steps() == [("search[Mercury]", True, 1), ("finish[SUPPORTS]", True, 2)]
    run = Run([reply("t", "verify it"), reply("a", "Finish[REFUTES]")])
    assert run.prompt(2) == P.final_answer_prompt()
    assert run.steps() == [("verify it", False, 0), ("finish[REFUTES]", True, 1)] and run.result.end_reason == "agent_done"


def test_a_reply_it_cannot_use_gets_the_error_message_and_the_same_prompt_again():
    """chatbot.py:370-371, 461-469: not JSON -> the JSON error message, no subtasks -> the error
    message naming the key; either way the loop sends the same prompt again, with no bound of
    its own (before: our repair message, and json_failures after three)."""
    bad = ["not json", '{"think": "no list"}', "```json\n{oops", "still not json"]
    run = Run(
        [reply("t0", "find Mercury", "decide"), *bad, reply("c", "Search[Mercury]"), reply("end"), reply("a", "Finish[SUPPORTS]")]
    )
    descend = P.descend_prompt("find Mercury")
    errors = [P.bad_json_text(), P.reply_error_text("'subtasks'"), P.bad_json_text(), P.bad_json_text()]
    assert run.sent(6)[1:] == [
        ("user", task_prompt(run.rules)),
        ("assistant", json.dumps({"think": "t0", "subtasks": ["find Mercury", "decide"]})),
        ("user", descend),
        *[m for text, error in zip(bad, errors, strict=True) for m in (("assistant", text), ("user", error), ("user", descend))],
    ]
    assert run.result.end_reason == "success" and run.result.json_repairs == 4
