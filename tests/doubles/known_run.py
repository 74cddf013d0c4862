"""Two small run folders with hand-chosen rows, written through PartWriter, whose every report
number is worked out by hand in the tests.

Run A (``runA``): Robotouille sync tasks t2/t6 with recap, react and recap level_3 on gpt-4o;
ALFWorld (one split, valid_unseen; task = type) with recap/react on gpt-4o and on a test-double
model. Rows are schema version 2 as the pipeline writes them; level_3 t6/84 was cut by the run
cap, so it counts in no success rate (it is in the coverage table). One unit (react t2/84) has a
superseded first attempt. Run B (``runB``) re-runs react t6/42 (same unit id, attempt 2, now a
success) and adds a recap unit with a 128-message window.
"""

from __future__ import annotations

from pathlib import Path

from recap.config import AgentConfig, ReCAPConfig, build_config
from schemas.parts import PartWriter
from schemas.records import (
    CallRecord,
    EpisodeRecord,
    EventRecord,
    MessageRecord,
    NodeRecord,
    NodeVersion,
    RunRecord,
    StepRecord,
)

RECAP = ReCAPConfig().to_json()
RECAP_128 = build_config(ReCAPConfig, window=128).to_json()
LEVEL_3 = build_config(ReCAPConfig, ablation="level_3").to_json()
REACT = AgentConfig().to_json()

SYNC = ("robotouille", "synchronous")
#: model label -> the model string sent to the provider
PROVIDER = {"gpt-4o": "openai/gpt-4o-2024-08-06", "scripted": "offline/expert"}
ALF = ("alfworld", "valid_unseen")


def unit_id(method: str, cfg: str, model: str, bench: tuple[str, str], task: str, inst: str, seed: int) -> str:
    tag = {RECAP: "orig", RECAP_128: "w128", LEVEL_3: "lvl3", REACT: "dflt"}[cfg]
    return f"{method}-{tag}-{model}-{bench[1][:4]}-{task}-{inst}-{seed}"


def episode(
    eid: str,
    method: str,
    cfg: str,
    model: str,
    bench: tuple[str, str],
    task: str,
    inst: str,
    seed: int,
    end: str,
    *,
    cost: float,
    prompt: int,
    cached: int,
    completion: int,
    calls: int,
    steps: int,
    attempt: int = 1,
    test_double: bool = False,
    ended_at: float = 100.0,
    max_depth: int = 0,
    error: str | None = None,
) -> EpisodeRecord:
    return EpisodeRecord(
        episode_id=eid,
        unit_id=unit_id(method, cfg, model, bench, task, inst, seed),
        attempt=attempt,
        benchmark=bench[0],
        split=bench[1],
        task=task,
        instance_id=inst,
        sampling_seed=seed,
        method=method,
        method_config=cfg,
        model=model,
        end_reason=end,
        success=end == "success",
        steps=steps,
        llm_calls=calls,
        prompt_tokens=prompt,
        cached_prompt_tokens=cached,
        completion_tokens=completion,
        cost_usd=cost,
        wall_s=10.0,
        step_cap=40,
        step_multiplier=4.0,
        optimal_steps=10,
        max_depth=max_depth,
        error=error,
        worker_id="w0",
        started_at=ended_at - 10.0,
        ended_at=ended_at,
        test_double=test_double,
        # schema version 2: the arm's label as the pipeline writes an unlabelled arm, the
        # ablation apart, the provider's model string
        label="recap[level_3]" if cfg == LEVEL_3 else method,
        ablation="level_3" if cfg == LEVEL_3 else None,
        provider_model=PROVIDER[model],
    )


def call(
    eid: str,
    ci: int,
    purpose: str,
    window: tuple[int, ...],
    *,
    model: str = "gpt-4o",
    status: str = "ok",
    prompt: int = 0,
    cached: int = 0,
    completion: int = 0,
    cost: float = 0.0,
    retries: int = 0,
    error_kind: str | None = None,
    node: int | None = None,
    response_seq: int | None = None,
    test_double: bool = False,
) -> CallRecord:
    return CallRecord(
        episode_id=eid,
        call_index=ci,
        call_key=f"{eid}#{ci}",
        purpose=purpose,
        window_seqs=window,
        model="" if status == "error" else model,
        status=status,
        node_id=node,
        response_seq=response_seq,
        error_kind=error_kind,
        error_message=f"{error_kind} happened" if error_kind else None,
        prompt_tokens=prompt,
        cached_prompt_tokens=cached,
        completion_tokens=completion,
        cost_usd=cost,
        latency_s=0.5,
        retries=retries,
        test_double=test_double,
    )


def step(
    eid: str,
    i: int,
    env_step: int,
    action: str,
    valid: bool,
    obs: str,
    *,
    done: bool = False,
    success: bool = False,
    node: int | None = None,
) -> StepRecord:
    return StepRecord(eid, i, env_step, action, valid, obs, done, success, node)


def node(
    eid: str,
    nid: int,
    parent: int | None,
    depth: int,
    ci: int,
    task: str,
    kind: str,
    status: str,
    versions: tuple[NodeVersion, ...],
    step_index: int | None = None,
) -> NodeRecord:
    return NodeRecord(eid, nid, parent, depth, ci, task, kind, status, versions, step_index)


def _v(version: int, think: str | None, subtasks: tuple[str, ...], ci: int | None = None, seq: int | None = None) -> NodeVersion:
    return NodeVersion(version, think, subtasks, ci, seq)


# -- run A ----------------------------------------------------------------------------------------

RUN_A_EPISODES = [
    # recap, gpt-4o, robotouille sync: 4 of 5
    episode(
        "A-recap-t2-42",
        "recap",
        RECAP,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        42,
        "success",
        cost=1.0,
        prompt=480,
        cached=200,
        completion=40,
        calls=4,
        steps=2,
        max_depth=3,
    ),
    episode(
        "A-recap-t2-84",
        "recap",
        RECAP,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        84,
        "success",
        cost=2.0,
        prompt=1000,
        cached=0,
        completion=100,
        calls=8,
        steps=5,
    ),
    episode(
        "A-recap-t6-42",
        "recap",
        RECAP,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        42,
        "success",
        cost=3.0,
        prompt=1500,
        cached=500,
        completion=150,
        calls=12,
        steps=10,
        max_depth=2,
    ),
    episode(
        "A-recap-t6-84",
        "recap",
        RECAP,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        84,
        "agent_done",
        cost=4.0,
        prompt=2000,
        cached=1000,
        completion=200,
        calls=16,
        steps=3,
    ),
    episode(
        "A-recap-t6-126",
        "recap",
        RECAP,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        126,
        "success",
        cost=2.0,
        prompt=1000,
        cached=0,
        completion=100,
        calls=10,
        steps=8,
    ),
    # react, gpt-4o, robotouille sync: 1 of 5 (t2/84 has a superseded first attempt)
    episode(
        "A-react-t2-42",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        42,
        "success",
        cost=0.5,
        prompt=300,
        cached=0,
        completion=30,
        calls=3,
        steps=3,
    ),
    episode(
        "A-react-t2-84-a1",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        84,
        "env_error",
        cost=1.125,
        prompt=400,
        cached=0,
        completion=20,
        calls=2,
        steps=1,
        ended_at=50.0,
        error="engine crashed",
    ),
    episode(
        "A-react-t2-84-a2",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        84,
        "step_cap",
        attempt=2,
        cost=0.5,
        prompt=300,
        cached=100,
        completion=20,
        calls=2,
        steps=6,
    ),
    episode(
        "A-react-t6-42",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        42,
        "step_cap",
        cost=1.0,
        prompt=500,
        cached=0,
        completion=50,
        calls=4,
        steps=1,
    ),
    episode(
        "A-react-t6-84",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        84,
        "llm_error",
        cost=0.25,
        prompt=100,
        cached=0,
        completion=10,
        calls=3,
        steps=0,
        error="bad_request: the provider refused the request",
    ),
    episode(
        "A-react-t6-126",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        126,
        "call_cap",
        cost=1.5,
        prompt=700,
        cached=0,
        completion=70,
        calls=6,
        steps=2,
    ),
    # recap level_3, gpt-4o, robotouille sync t6: 1 of 3
    episode(
        "A-lvl3-t6-42",
        "recap",
        LEVEL_3,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        42,
        "step_cap",
        cost=2.0,
        prompt=900,
        cached=0,
        completion=90,
        calls=9,
        steps=4,
    ),
    episode(
        "A-lvl3-t6-84",
        "recap",
        LEVEL_3,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        84,
        "budget_exhausted",
        cost=5.0,
        prompt=2500,
        cached=0,
        completion=250,
        calls=20,
        steps=7,
    ),
    episode(
        "A-lvl3-t6-126",
        "recap",
        LEVEL_3,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        126,
        "success",
        cost=1.0,
        prompt=450,
        cached=0,
        completion=45,
        calls=5,
        steps=6,
    ),
    # ALFWorld ood: gpt-4o and the test double "scripted"
    episode(
        "A-recap-alf-p1",
        "recap",
        RECAP,
        "gpt-4o",
        ALF,
        "put",
        "p1",
        1,
        "success",
        cost=0.75,
        prompt=300,
        cached=0,
        completion=30,
        calls=3,
        steps=2,
    ),
    episode(
        "A-react-alf-p1",
        "react",
        REACT,
        "gpt-4o",
        ALF,
        "put",
        "p1",
        1,
        "json_failures",
        cost=0.25,
        prompt=100,
        cached=0,
        completion=10,
        calls=2,
        steps=1,
    ),
    episode(
        "A-recap-alf-p1-td",
        "recap",
        RECAP,
        "scripted",
        ALF,
        "put",
        "p1",
        1,
        "success",
        cost=0.0,
        prompt=200,
        cached=0,
        completion=20,
        calls=2,
        steps=2,
        test_double=True,
    ),
    episode(
        "A-recap-alf-p2-td",
        "recap",
        RECAP,
        "scripted",
        ALF,
        "put",
        "p2",
        1,
        "env_error",
        cost=0.0,
        prompt=50,
        cached=0,
        completion=5,
        calls=1,
        steps=0,
        test_double=True,
        error="reset failed",
    ),
    episode(
        "A-react-alf-p1-td",
        "react",
        REACT,
        "scripted",
        ALF,
        "put",
        "p1",
        1,
        "episode_limit",
        cost=0.0,
        prompt=5000,
        cached=0,
        completion=500,
        calls=10,
        steps=4,
        test_double=True,
    ),
]

RUN_A_CALLS = [
    call("A-recap-t2-42", 0, "task", (0, 1), prompt=100, cached=0, completion=10, cost=0.25, node=0, response_seq=2),
    call("A-recap-t2-42", 1, "descend", (0, 1, 2, 3), prompt=120, cached=50, completion=10, cost=0.25, node=1, response_seq=4),
    call(
        "A-recap-t2-42", 2, "repair", (0, 1, 2, 3, 4, 5), prompt=140, cached=50, completion=10, cost=0.25, node=1, response_seq=6
    ),
    call("A-recap-t2-42", 3, "leaf_done", (0, 1, 6, 7), prompt=120, cached=100, completion=10, cost=0.25, node=0, response_seq=8),
    call("A-react-t2-84-a1", 0, "task", (0, 1), prompt=400, completion=20, cost=1.0),
    call("A-react-t2-84-a1", 1, "observation", (0, 1, 2, 3), status="error", error_kind="server_error", retries=2, cost=0.125),
    call("A-react-t2-84-a2", 0, "task", (0, 1), prompt=150, cached=50, completion=10, cost=0.25),
    call("A-react-t2-84-a2", 1, "observation", (0, 1, 2, 3), prompt=150, cached=50, completion=10, cost=0.25),
    call("A-react-t6-84", 0, "task", (0, 1), status="error", error_kind="timeout", retries=1),
    call("A-react-t6-84", 1, "task", (0, 1), prompt=100, completion=10, cost=0.25),
    call("A-react-t6-84", 2, "observation", (0, 1, 2, 3), status="error", error_kind="rate_limit", retries=3),
    call("A-lost-1", 0, "task", (0, 1), prompt=200, completion=20, cost=0.5),
    call("A-recap-alf-p1-td", 0, "task", (0, 1), model="scripted", prompt=100, completion=10, test_double=True),
    call("A-recap-alf-p1-td", 1, "leaf_done", (0, 1, 2, 3), model="scripted", prompt=100, completion=10, test_double=True),
]

RUN_A_STEPS = [
    # recap t2/42: the viewer episode
    step("A-recap-t2-42", 0, 1, "pick onion", True, "You hold the onion.", node=3),
    step("A-recap-t2-42", 1, 1, "place onion on table9", False, "You hold the onion.", node=6),
    step("A-recap-t2-42", 2, 2, "serve", True, "Served.", done=True, success=True, node=2),
    # react t2/84 attempt 2: a-b-a-b-a-b with the same observations -> repeated_action_loop (cycle 2)
    *[step("A-react-t2-84-a2", i, i + 1, a, True, o) for i, (a, o) in enumerate([("go a", "at a"), ("go b", "at b")] * 3)],
    # react t6/42: three invalid attempts in a row -> invalid_action_loop
    step("A-react-t6-42", 0, 1, "x", True, "o1"),
    step("A-react-t6-42", 1, 1, "bad1", False, "o1"),
    step("A-react-t6-42", 2, 1, "bad2", False, "o1"),
    step("A-react-t6-42", 3, 1, "bad3", False, "o1"),
    # react t6/126: invalid attempts never 3 in a row nor 3 times the same; repeats change the
    # observation -> plain call_cap
    step("A-react-t6-126", 0, 1, "a", True, "o1"),
    step("A-react-t6-126", 1, 1, "z", False, "o1"),
    step("A-react-t6-126", 2, 2, "a", True, "o2"),
    step("A-react-t6-126", 3, 2, "z", False, "o2"),
    # recap t6/84: the same action and observation three times (cycle 1 needs four) -> agent_done_early
    *[step("A-recap-t6-84", i, i + 1, "a", True, "same") for i in range(3)],
    # level_3 t6/42: the same action four times but the observation changes -> plain step_cap
    *[step("A-lvl3-t6-42", i, i + 1, "cut lettuce", True, f"cut {i + 1}") for i in range(4)],
]

T2 = "A-recap-t2-42"
RUN_A_NODES = [
    # max depth 3 (levels 4); non-leaf nodes 0 (3 children), 1 (2), 4 (1): branching 2.0; one leaf failure
    node(
        T2,
        0,
        None,
        0,
        0,
        "make a sandwich",
        "root",
        "done",
        (_v(0, "plan it", ("prepare onion", "serve", "clean"), 0, 2), _v(1, "onion done", ("serve", "clean"), 3, 8)),
        None,
    ),
    node(
        T2,
        1,
        0,
        1,
        0,
        "prepare onion",
        "composite",
        "done",
        (_v(0, "get it", ("pick onion", "put down"), 1, 4), _v(1, "repaired", ("pick onion", "put down"), 2, 6)),
    ),
    node(T2, 2, 0, 1, 1, "serve", "primitive", "done", (_v(0, None, ("serve",)),), step_index=2),
    node(T2, 3, 1, 2, 0, "pick onion", "primitive", "done", (_v(0, None, ("pick onion",)),), step_index=0),
    node(T2, 4, 1, 2, 1, "put down", "composite", "done", (_v(0, "where", ("place onion on table9",)),)),
    node(T2, 5, 0, 1, 2, "clean", "primitive", "done", (_v(0, None, ("clean",)),)),
    node(
        T2, 6, 4, 3, 0, "place onion on table9", "primitive", "failed", (_v(0, None, ("place onion on table9",)),), step_index=1
    ),
    # recap t6/42: depth 2 (levels 3); branching (2 + 1) / 2 = 1.5
    node("A-recap-t6-42", 0, None, 0, 0, "make a burger", "root", "done", (_v(0, "t", ("a", "b")),)),
    node("A-recap-t6-42", 1, 0, 1, 0, "a", "composite", "done", (_v(0, "t", ("a1",)),)),
    node("A-recap-t6-42", 2, 0, 1, 1, "b", "primitive", "done", (_v(0, None, ("b",)),)),
    node("A-recap-t6-42", 3, 1, 2, 0, "a1", "primitive", "done", (_v(0, None, ("a1",)),)),
]

RUN_A_MESSAGES = [
    MessageRecord(T2, 0, "user", "demonstration", "DEMO TEXT", None, True),
    MessageRecord(T2, 1, "user", "task", "TASK: make a sandwich", 0, True),
    MessageRecord(T2, 2, "assistant", "reply", '{"think": "plan it", "subtasks": ["prepare onion", "serve", "clean"]}', 0),
    MessageRecord(T2, 3, "user", "descend", "Work on: prepare onion", 1),
    MessageRecord(T2, 4, "assistant", "reply", "not json <oops>", 1),
    MessageRecord(T2, 5, "user", "repair", "Answer again with JSON", 1),
    MessageRecord(T2, 6, "assistant", "reply", '{"think": "repaired", "subtasks": ["pick onion", "put down"]}', 1),
    MessageRecord(T2, 7, "user", "leaf_done", "Done: prepare onion. Observation: You hold the onion.", 0),
    MessageRecord(T2, 8, "assistant", "reply", '{"think": "onion done", "subtasks": ["serve", "clean"]}', 0),
]

RUN_A_EVENTS = [
    EventRecord(1.0, "gateway", "retry", "warning", "A-react-t2-84-a1", None, '{"kind": "server_error"}'),
    EventRecord(2.0, "gateway", "retry", "warning", "A-react-t6-84", None, '{"kind": "rate_limit"}'),
    EventRecord(3.0, "pipeline", "worker_restart", "error", None, None, "{}"),
]

RUN_A_RUN = [
    RunRecord(1000.0, "name: sweepA\n", "hashA", "{}", "abc123", "hostA", "recap run sweepA.yaml"),
    RunRecord(2000.0, "name: sweepA\n", "hashA", "{}", "abc123", "hostA2", "recap run sweepA.yaml --resume"),
]

# -- run B ----------------------------------------------------------------------------------------

RUN_B_EPISODES = [
    episode(
        "B-recap128-t2-42",
        "recap",
        RECAP_128,
        "gpt-4o",
        SYNC,
        "t2",
        "i2",
        42,
        "success",
        cost=1.5,
        prompt=700,
        cached=0,
        completion=70,
        calls=6,
        steps=4,
    ),
    episode(
        "B-react-t6-42-a2",
        "react",
        REACT,
        "gpt-4o",
        SYNC,
        "t6",
        "i6",
        42,
        "success",
        attempt=2,
        cost=0.75,
        prompt=350,
        cached=0,
        completion=35,
        calls=3,
        steps=5,
        ended_at=500.0,
    ),
]
RUN_B_RUN = [RunRecord(3000.0, "name: sweepB\n", "hashB", "{}", None, "hostB", "recap run sweepB.yaml")]


def write_run_a(run_dir: Path) -> Path:
    """Run A in several part files per table (two writers, several batches)."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text('{"run_id": "runA", "spec_hash": "hashA"}')
    w1, w2 = PartWriter(run_dir, writer="sink0001"), PartWriter(run_dir, writer="gate0001")
    w1.write_records("runA", RUN_A_EPISODES[:8])
    w1.write_records("runA", RUN_A_EPISODES[8:])
    w2.write_records("runA", RUN_A_CALLS[:6])
    w2.write_records("runA", RUN_A_CALLS[6:])
    w1.write_records("runA", RUN_A_STEPS + RUN_A_NODES + RUN_A_MESSAGES + RUN_A_EVENTS + RUN_A_RUN)
    return run_dir


def write_run_b(run_dir: Path) -> Path:
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / "run.json").write_text('{"run_id": "runB", "spec_hash": "hashB"}')
    PartWriter(run_dir, writer="sink0002").write_records("runB", RUN_B_EPISODES + RUN_B_RUN)
    return run_dir
