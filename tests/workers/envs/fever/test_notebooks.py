"""FEVER's four baselines as the authors' notebooks ran them: the sample, the text read from the
notebooks at run time, the loops (in-process, against the Wikipedia stand-in) and the settings
``prompts: release`` implies. The notebooks are read from ../shared/data/recap-release."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from recap import methods
from recap.config import build_config
from recap.llm import LLMError, LLMRequest, LLMResponse
from tests.conftest import SHARED_DATA
from tests.workers.envs.fever import notebook_replay as R
from tests.workers.envs.fever.notebook_runs import FEVER, available, episodes
from workers.envs.fever import BENCHMARK
from workers.envs.fever.claims import NOTEBOOK_SEED, PAPER_SEED, load_claims, paper_indices
from workers.envs.fever.ratelimit import TokenBucket
from workers.envs.fever.standin import Answer, StandIn
from workers.envs.registry import get_benchmark
from workers.llm.offline.replay import ReplayError
from workers.llm.offline.transcript import TranscriptIndex
from workers.release import fever_notebooks
from workers.release.texts import ReleaseMissing, release_prompt, release_text

CLAIMS = SHARED_DATA / "fever"
RELEASE = SHARED_DATA / "recap-release"
needs_release = pytest.mark.skipif(not available(), reason="the release's FEVER notebooks are not in ../shared/data")
needs_claims = pytest.mark.skipif(not (CLAIMS / "paper_dev.jsonl").is_file(), reason="no FEVER claims in ../shared/data")


# -- item 7: the sample ----------------------------------------------------------------------------


def test_the_two_release_samples_share_four_claims():
    notebooks, main = paper_indices(NOTEBOOK_SEED), paper_indices()
    assert notebooks[:4] == [3687, 6238, 5388, 3522] and main[:5] == [1547, 2054, 478, 3245, 1119]
    assert len(set(notebooks) & set(main)) == 4


@needs_claims
def test_sample_seed_picks_the_paper_selector_sample(tmp_path):
    claims = load_claims(CLAIMS)
    seed_233 = BENCHMARK.list_instances_for("paper", {"sample_seed": 233, "data_dir": str(CLAIMS)})
    assert seed_233 == [claims[i].instance_id for i in paper_indices(233)]
    assert BENCHMARK.list_instances_for("paper", {"data_dir": str(CLAIMS)}) == BENCHMARK.list_instances_for(
        "paper", {"sample_seed": PAPER_SEED, "data_dir": str(CLAIMS)}
    )
    assert seed_233[0] == claims[3687].instance_id
    with pytest.raises(ValueError, match="sample_seed must be a non-negative integer .* got 'x'"):
        BENCHMARK.list_instances_for("paper", {"sample_seed": "x", "data_dir": str(CLAIMS)})
    env = BENCHMARK.make(seed_233[0], data_dir=str(CLAIMS), sample_seed=233, wikipedia_url="http://127.0.0.1:9")
    assert env.reset().observation == f"Claim: {claims[3687].claim}"


# -- item 5: the text, read from the notebooks -----------------------------------------------------


@needs_release
@pytest.mark.parametrize("method", ["react", "act"])
def test_react_and_act_read_the_demonstration_and_the_final_round_sentence(method):
    prompt = release_prompt(RELEASE, method, "fever", "dev", "SUPPORTS")
    assert prompt is not None and prompt.first_turn == "notebook"
    assert prompt.messages == (("user", R.demonstration(method)),)
    assert (prompt.rounds, prompt.final_round, prompt.final_sentence) == (10, 10, R.final_sentence(method))
    text = release_text(RELEASE, method, "fever", "dev", "SUPPORTS")
    assert text.files == (f"fever-recap/{'React.ipynb' if method == 'react' else 'baseline_act.ipynb'}",)
    assert R.demonstration(method) in text.text and R.final_sentence(method) in text.text


def _cell_source(name: str, cell: int) -> str:
    return "".join(json.loads((FEVER / name).read_text(encoding="utf-8-sig"))["cells"][cell]["source"])


@needs_release
@pytest.mark.parametrize(
    ("method", "name", "after"),
    [("cot", "baseline_cot.ipynb", "\nThought:"), ("standard", "baseline_standard.ipynb", "\nAnswer:")],
)
def test_cot_and_standard_read_the_one_prompt_around_the_question(method, name, after):
    prompt = release_prompt(RELEASE, method, "fever", "dev", "SUPPORTS")
    assert prompt is not None and prompt.messages == () and prompt.claim_frame is not None
    before, got_after = prompt.claim_frame
    assert got_after == after and before.endswith("Claim: ")
    # the literal as the cell writes it (newlines escaped), and nothing of the cell's code
    body = before[: before.rindex("Claim: ")].rstrip("\n")
    assert body.replace("\n", "\\n")[:200] in _cell_source(name, 2)
    assert "llm(" not in before and "{question}" not in before


@needs_release
def test_an_edited_notebook_is_refused_in_one_line(tmp_path):
    folder = tmp_path / "release"
    shutil.copytree(RELEASE / "fever-recap", folder / "fever-recap", ignore=shutil.ignore_patterns("MATRIX", "hotpotqa"))
    nb = folder / "fever-recap" / "React.ipynb"
    data = json.loads(nb.read_text(encoding="utf-8-sig"))
    data["cells"][4]["source"] = ["print('no loop here')\n"]
    nb.write_text(json.dumps(data), encoding="utf-8")
    with pytest.raises(ReleaseMissing, match=r"fever-recap/React.ipynb does not hold the expected notebook:react"):
        release_text(folder, "react", "fever", "dev", "SUPPORTS")
    (folder / "fever-recap" / "baseline_act.ipynb").unlink()
    with pytest.raises(ReleaseMissing, match="baseline_act.ipynb is missing"):
        release_text(folder, "act", "fever", "dev", "SUPPORTS")


# -- the settings ----------------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["react", "act", "cot", "standard"])
def test_prompts_release_on_fever_sends_plain_text_and_released_no_temperature(method):
    _agent, cfg_cls = methods.method_classes(method)
    cfg = build_config(cfg_cls, profile="released", benchmark=get_benchmark("fever"), prompts="release")
    assert (cfg.json_mode, cfg.reply_format, cfg.temperature) == (False, "text", None)
    if method in ("react", "act"):
        assert cfg.history == "all"


# -- item 8: CoT and Standard's one call -----------------------------------------------------------


class Scripted:
    """A model answering each call with the next scripted reply and keeping every request."""

    def __init__(self, replies: list[str]) -> None:
        self.replies = list(replies)
        self.requests: list[LLMRequest] = []

    def complete(self, request: LLMRequest) -> LLMResponse:
        self.requests.append(request)
        return LLMResponse(text=self.replies.pop(0), model="scripted")


def _play(method: str, claim_index: int, replies: list[str], wiki: str = "http://127.0.0.1:9"):
    agent_cls, cfg_cls = methods.method_classes(method)
    agent = agent_cls(build_config(cfg_cls, profile="released", benchmark=get_benchmark("fever"), prompts="release"))
    claim = load_claims(CLAIMS)[claim_index]
    env = BENCHMARK.make(claim.instance_id, data_dir=str(CLAIMS), wikipedia_url=wiki, limiter=TokenBucket(1e6, 10**6))
    client = Scripted(replies)
    steps: list = []
    result = agent.run(
        env,
        client,
        episode_id="e",
        emit=lambda r: steps.append(r),
        demonstration=release_prompt(RELEASE, method, "fever", "dev", "x"),
    )
    return claim, client, result, [s for s in steps if type(s).__name__ == "StepRecord"]


@needs_release
@needs_claims
def test_cot_sends_one_user_message_and_finishes_with_the_text_after_the_last_answer():
    claim, client, result, steps = _play("cot", 3687, ["Thought: it says Answer: SUPPORTS first.\nAnswer: REFUTES "])
    before, after = release_prompt(RELEASE, "cot", "fever", "dev", "x").claim_frame  # type: ignore[misc]
    (request,) = client.requests
    assert [(m.role, m.content) for m in request.messages] == [("user", f"{before}Claim: {claim.claim}{after}")]
    assert (request.stop, request.temperature, request.json_mode) == ((), None, False)
    assert [s.action for s in steps] == ["finish[REFUTES]"]
    assert result.success == (claim.label == "REFUTES")


@needs_release
@needs_claims
def test_standard_finishes_with_the_whole_reply():
    claim, client, result, steps = _play("standard", 3687, [f"  {'NOT ENOUGH INFO'}\n"])
    before, after = release_prompt(RELEASE, "standard", "fever", "dev", "x").claim_frame  # type: ignore[misc]
    assert [(m.role, m.content) for m in client.requests[0].messages] == [("user", f"{before}Claim: {claim.claim}{after}")]
    assert [s.action for s in steps] == ["finish[NOT ENOUGH INFO]"]
    assert result.success == (claim.label == "NOT ENOUGH INFO")


# -- item 6: ReAct and Act's loop, message by message ----------------------------------------------


@needs_release
@needs_claims
def test_react_re_asks_for_the_action_and_keeps_one_assistant_message_per_round():
    server = StandIn({"Eric Church": [Answer(body=R.article(["Kenneth Eric Church is a singer.", "He sings."]))]}).start()
    try:
        claim, client, result, steps = _play(
            "react",
            6238,
            [
                "I should search Eric Church.\nmore text",  # no "\nAction 1: ": the re-ask
                "Search[Eric Church]",
                "Thought 2: He is a singer.\nAction 2: Finish[REFUTES]",
            ],
            server.base_url,
        )
    finally:
        server.stop()
    demo, final = R.demonstration("react"), R.final_sentence("react")
    first = f"Claim: {claim.claim}\nThought 1:"
    step1 = "Thought 1: I should search Eric Church.\nAction 1: Search[Eric Church]\nObservation 1: Kenneth Eric Church is a singer. He sings.\n"
    assert [([(m.role, m.content) for m in r.messages], r.stop) for r in client.requests] == [
        ([("user", demo), ("user", first)], ("\nObservation 1:",)),
        ([("user", demo), ("user", first), ("user", "Thought 1: I should search Eric Church.\nAction 1:")], ("\n",)),
        (
            [
                ("user", demo),
                ("user", first),
                ("user", "Thought 1: I should search Eric Church.\nAction 1:"),
                ("assistant", step1),
                ("user", "Thought 2:"),
            ],
            ("\nObservation 2:",),
        ),
    ]
    assert all(r.temperature is None for r in client.requests)
    assert [s.action for s in steps] == ["search[Eric Church]", "finish[REFUTES]"]
    assert result.success == (claim.label == "REFUTES")
    assert final not in "".join(m.content for r in client.requests for m in r.messages)


@needs_release
@needs_claims
def test_act_takes_the_text_after_the_last_label_and_ends_after_ten_rounds():
    claim, client, result, steps = _play("act", 3687, [f"Action {i}: Think[round {i}]" for i in range(1, 11)])
    assert len(client.requests) == 10 and result.success is False
    assert [s.action for s in steps] == [f"think[round {i}]" for i in range(1, 11)]
    last = [(m.role, m.content) for m in client.requests[-1].messages]
    assert last[-1] == ("user", R.final_sentence("act") + "Action 10:")
    assert last[-2] == ("assistant", "Action 9: Think[round 9]\nObservation 9: Nice thought.\n")
    assert client.requests[-1].stop == ("\nObservation 10:",)
    assert len(last) == 1 + 2 * 9 + 1


@needs_release
@needs_claims
def test_an_empty_action_ends_the_episode_unsuccessful():
    _claim, client, result, steps = _play("act", 3687, ["Action 1:"])
    assert len(client.requests) == 1 and steps == [] and result.success is False
    assert result.end_reason == "agent_done" and "empty action" in (result.error or "")


# -- the double and the whole printed runs, in-process ---------------------------------------------


def test_the_transcript_double_answers_only_the_same_messages_and_stop_list(tmp_path):
    path = tmp_path / "t.jsonl"
    path.write_text(
        json.dumps({"messages": [{"role": "user", "content": "q"}], "stop": ["\nObservation 1:"], "reply": "a"}) + "\n"
    )
    index = TranscriptIndex.load(path)
    assert index.answer([{"role": "user", "content": "q"}], ["\nObservation 1:"]) == "a"
    with pytest.raises(
        ReplayError, match=r"no call in t.jsonl with this message list and stop list \(1 messages, stop \['\\n'\]\)"
    ):
        index.answer([{"role": "user", "content": "q"}], ["\n"])
    with pytest.raises(ReplayError):
        index.answer([{"role": "user", "content": "q "}], ["\nObservation 1:"])
    assert LLMRequest((), "e", 0, "task", stop=("\n",)).stop_params() == {"stop": ["\n"]}
    assert LLMRequest((), "e", 0, "task").stop_params() == {}


class Recorded:
    """The printed runs' replies, answered only to the request the notebook's loop built."""

    def __init__(self, calls: list[R.Call]) -> None:
        self.table = {(c.messages, c.stop): c.reply for c in calls}
        self.unanswered = 0

    def complete(self, request: LLMRequest) -> LLMResponse:
        key = (tuple((m.role, m.content) for m in request.messages), request.stop)
        if key not in self.table:
            self.unanswered += 1
            raise LLMError("bad_request", "not a request the notebook made")
        return LLMResponse(text=self.table[key], model="recorded")


@needs_release
@needs_claims
@pytest.mark.parametrize(("method", "printed"), [("react", 127), ("act", 108)])
def test_the_printed_runs_replay_in_process_to_the_printed_totals(method, printed):
    """All 200 printed episodes of each notebook through the agent and the environment (no Ray):
    every request answered (messages and stop list as the loop built them), each verdict the
    printed ``em``. The same through ``recap run``: test_notebook_replay.py."""
    runs = episodes(method)
    demo, final = R.demonstration(method), R.final_sentence(method)
    client = Recorded([c for e in runs for c in R.expected_calls(method, e, demo, final)])
    agent_cls, cfg_cls = methods.method_classes(method)
    agent = agent_cls(build_config(cfg_cls, profile="released", benchmark=get_benchmark("fever"), prompts="release"))
    prompt = release_prompt(RELEASE, method, "fever", "dev", "x")
    claims = load_claims(CLAIMS)
    server = StandIn(R.routes(runs)).start()
    wins = 0
    try:
        for e in runs:
            env = BENCHMARK.make(
                claims[e.index].instance_id, data_dir=str(CLAIMS), wikipedia_url=server.base_url, limiter=TokenBucket(1e6, 10**6)
            )
            result = agent.run(env, client, episode_id=f"e{e.index}", demonstration=prompt)
            assert (result.success, client.unanswered) == (bool(e.info["em"]), 0), e.index
            wins += int(result.success)
    finally:
        server.stop()
    assert (wins, len(runs)) == (printed, 200)


def test_fever_notebooks_covers_the_four_baselines_only():
    assert [m for m in ("recap", "react", "act", "cot", "standard", "adapt") if fever_notebooks.covers(m)] == [
        "react",
        "act",
        "cot",
        "standard",
    ]
    assert Path(fever_notebooks.notebook_path("cot")).name == "baseline_cot.ipynb"
