"""The authors' printed GPT-4o runs of React.ipynb and baseline_act.ipynb, replayed through ``recap run``.

Each notebook's saved output (read at test time from ../shared/data/recap-release, never stored
here) is parsed into its 200 episodes (:mod:`.notebook_runs`). From each, the test rebuilds every
request the notebook's loop made (:func:`.notebook_replay.expected_calls`: message list, stop list,
the reply it got) into a transcript for the ``offline/replay`` double, which answers a request only
when its message list *and* stop list equal a recorded one; and it serves, from a Wikipedia
stand-in, pages that give the printed observations (:func:`.notebook_replay.routes`). Then a sweep
(``profile: released``, ``prompts: release``, ``sample_seed: 233``) runs on the local Ray cluster.

What it shows: every call was answered (so each request's messages and stop list were the
notebook's), the calls' message lists read back from the run's tables equal the rebuilt ones in
order, each claim's success equals the notebook's printed ``em``, and the totals are the printed
ReAct 127/200 and Act 108/200 (the full replay, ``slow``); the default suite replays a stated
subset (:data:`SUBSET`) chosen to cover the loop's paths.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from tests.conftest import SHARED_DATA
from tests.workers.envs.fever import notebook_replay as R
from tests.workers.envs.fever.notebook_runs import Episode, available, episodes
from workers.envs.fever.claims import NOTEBOOK_SEED, load_claims, paper_indices
from workers.envs.fever.standin import StandIn

CLAIMS = SHARED_DATA / "fever"
pytestmark = pytest.mark.skipif(
    not available() or not (CLAIMS / "paper_dev.jsonl").is_file(),
    reason="the release's notebooks or the FEVER claims are not in ../shared/data",
)
#: printed totals (the last running line of each notebook's loop cell)
PRINTED = {"react": 127, "act": 108}


def subset() -> list[int]:
    """The default suite's claims (indices of the notebooks' shared sample): the first six whose
    pages one stand-in can serve to both methods (the notebooks ran on different days, and a
    search both made was sometimes answered differently), plus for each path of the loop not
    among them the first such claim where either notebook took it (ReAct's re-ask, ten rounds
    without a verdict, an invalid multi-line action, a lookup that found a sentence, one that
    found none, a search the release sent with ``&``, a disambiguation retry). Both methods
    replay every one of them."""
    runs = {method: {e.index: e for e in episodes(method)} for method in ("react", "act")}
    chosen: list[int] = []

    def fits(index: int) -> bool:
        try:
            merged_routes({m: [r[i] for i in [*chosen, index]] for m, r in runs.items()})
        except ConflictingPages:
            return False
        return True

    for index in runs["react"]:
        if len(chosen) == 6:
            break
        if fits(index):
            chosen.append(index)
    features = [
        lambda e: any(s.bad for s in e.steps),
        lambda e: len(e.steps) == R.ROUNDS and e.info["answer"] == "",
        lambda e: any(s.observation.startswith("Invalid action:") and "\n" in s.action for s in e.steps),
        lambda e: any(s.observation.startswith("(Result") for s in e.steps),
        lambda e: any(s.observation == "No more results.\n" for s in e.steps),
        lambda e: any("&" in s.action and s.action.lower().startswith("search[") for s in e.steps),
        lambda e: any(s.observation.startswith("Could not find [") for s in e.steps),
    ]
    for has in features:
        for method_runs in runs.values():
            if not any(has(method_runs[i]) for i in chosen):
                found = next((i for i, e in method_runs.items() if has(e) and fits(i)), None)
                if found is not None and found not in chosen:
                    chosen.append(found)
    return chosen


def sweep_text(out: Path, methods: list[str], transcript: Path, wiki: str, instances: list[str] | None) -> str:
    which = "    tasks: [paper]\n" if instances is None else f"    instances: [{', '.join(instances)}]\n"
    entries = "".join(f"  - {{method: {m}, profile: released, prompts: release}}\n" for m in methods)
    return f"""run: {out.name}
output: {out}
models:
  - model: offline/replay
    api_base: {transcript}
methods:
{entries}environments:
  - benchmark: fever
{which}    options: {{wikipedia_url: "{wiki}", wikipedia_rate: 10, sample_seed: {NOTEBOOK_SEED}, data_dir: "{CLAIMS}"}}
workers: 2
"""


class ConflictingPages(AssertionError):
    """Two printed runs saw different answers to the same search."""


def merged_routes(runs: dict[str, list[Episode]]) -> dict:
    """One stand-in's pages for every method's episodes (the two notebooks ran on different days:
    a search both made may have been answered differently, which one stand-in cannot serve)."""
    out: dict = {}
    for method_runs in runs.values():
        for key, answers in R.routes(method_runs).items():
            if out.get(key, answers)[0].body != answers[0].body:
                raise ConflictingPages(f"the runs saw different pages for {key!r}")
            out[key] = answers
    return out


def replay(runs: dict[str, list[Episode]], tmp_path: Path, *, whole: bool) -> None:
    """Replay ``runs`` (method -> printed episodes) through one ``recap run`` sweep and check every
    request, each verdict and the totals."""
    expected: dict[tuple[str, int], list[R.Call]] = {}
    for method, method_runs in runs.items():
        demo, final = R.demonstration(method), R.final_sentence(method)
        for e in method_runs:
            expected[(method, e.index)] = R.expected_calls(method, e, demo, final)
    transcript = tmp_path / "transcript.jsonl"
    transcript.write_text("".join(c.as_json() + "\n" for calls in expected.values() for c in calls), encoding="utf-8")
    claims = load_claims(CLAIMS)
    by_id = {(method, claims[e.index].instance_id): e for method, method_runs in runs.items() for e in method_runs}
    for method, e in ((m, e) for m, rs in runs.items() for e in rs):  # the printed claim is the file's line at the printed index
        assert claims[e.index].claim == e.claim, (method, e.index)
    server = StandIn(merged_routes(runs)).start()
    out = tmp_path / "run"
    spec = tmp_path / "sweep.yaml"
    instances = sorted({instance for _m, instance in by_id})
    spec.write_text(sweep_text(out, list(runs), transcript, server.base_url, None if whole else instances))
    try:
        code = main(["run", str(spec), "--progress", "off"])
    finally:
        server.stop()
    assert code == 0

    con, bad = open_tables(RunStore(out))
    assert bad == []
    rows = con.execute("select episode_id, method, instance_id, success, end_reason from episodes").fetchall()
    assert sorted((r[1], r[2]) for r in rows) == sorted(by_id)
    # every call answered: the double answers only a request whose messages and stop list are a
    # recorded one's, so a single differing request would have failed its episode (llm_error)
    texts = {(m[0], m[1]): (m[2], m[3]) for m in con.execute("select episode_id, seq, role, content from messages").fetchall()}
    for episode_id, method, instance_id, success, end in rows:
        printed = by_id[(method, instance_id)]
        assert end != "llm_error", (method, instance_id)
        assert bool(success) == bool(printed.info["em"]), (method, instance_id)
        calls = con.execute(
            "select status, window_seqs from llm_calls where episode_id = ? order by call_index", [episode_id]
        ).fetchall()
        assert {status for status, _w in calls} == {"ok"}
        sent = [tuple(texts[(episode_id, s)] for s in window) for _status, window in calls]
        assert sent == [c.messages for c in expected[(method, printed.index)]], (method, instance_id)
    for method, method_runs in runs.items():
        wins = sum(bool(r[3]) for r in rows if r[1] == method)
        assert wins == sum(e.info["em"] for e in method_runs)
        if whole:
            assert (wins, len(method_runs)) == (PRINTED[method], 200)


@pytest.mark.parametrize("method", ["react", "act"])
def test_the_notebook_runs_parse_to_the_printed_totals_on_the_seed_233_sample(method):
    runs = episodes(method)
    assert [e.index for e in runs] == paper_indices(NOTEBOOK_SEED)
    assert sum(e.info["em"] for e in runs) == runs[-1].running_sum == PRINTED[method]
    # the steps the info dict counts: the printed rounds, plus the finish[] after ten without a verdict
    assert all(e.info["steps"] == len(e.steps) + (e.info["answer"] == "") for e in runs)


def test_a_subset_of_the_notebook_runs_replays_through_recap_run(tmp_path, ray_address):
    """One sweep of both methods on :func:`subset`'s claims."""
    chosen = subset()
    runs = {method: [e for e in episodes(method) if e.index in chosen] for method in ("react", "act")}
    assert [len(r) for r in runs.values()] == [len(chosen)] * 2 and len(chosen) >= 8
    replay(runs, tmp_path, whole=False)


@pytest.mark.slow  # 2 x 200 episodes, ~2,000 stand-in searches at 10 a second
@pytest.mark.parametrize("method", ["react", "act"])
def test_the_whole_notebook_runs_replay_to_127_and_108_of_200(method, tmp_path, ray_address):
    replay({method: episodes(method)}, tmp_path, whole=True)
