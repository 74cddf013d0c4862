"""Properties over random scripted ReCAP episodes: the window bound and the active path."""

from __future__ import annotations

import json
import random
import sys

from hypothesis import given, settings
from hypothesis import strategies as st

from recap.blocksworld import BENCHMARK
from recap.config import ReCAPConfig
from recap.llm import LLMRequest
from tests.recap.recap_harness import run_recap

REFINES = {"leaf_done", "leaf_judge", "leaf_fail", "nonleaf_done", "nonleaf_judge"}


def active_loops() -> int:
    """How many ReCAP node loops are on the call stack right now (the recursion depth). The frames
    are walked directly: ``inspect.stack()`` resolves every frame's source file (a stat and a
    module scan each), ~85 % of this test's time under pytest's and hypothesis's deep stacks."""
    n, frame = 0, sys._getframe(1)
    while frame is not None:
        code = frame.f_code
        n += code.co_name == "_loop" and "recap_agent" in code.co_filename
        frame = frame.f_back
    return n


class RandomModel:
    def __init__(self, seed: int):
        self.rng = random.Random(seed)
        self.observed: list[tuple[str, int, int]] = []

    def __call__(self, req: LLMRequest) -> str:
        self.observed.append((req.purpose, req.hints["depth"], active_loops()))
        r = self.rng.random()
        if r < 0.05:
            return "not json at all"
        valid = req.hints["valid_actions"] or []
        k = self.rng.randint(0, 4)
        pool = valid + ["do something odd", "sub-goal alpha", "sub-goal beta", "sub-goal gamma"]
        subtasks = [self.rng.choice(pool) for _ in range(k)]
        return json.dumps({"think": f"t{len(self.observed)}", "subtasks": subtasks})


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    window=st.sampled_from([2, 4, 6, 10]),
    mode=st.sampled_from(["pair", "block"]),
    level=st.sampled_from([None, 2, 3, 4]),
)
def test_window_bound_and_active_path(seed, window, mode, level):
    env = BENCHMARK.make(f"blocksworld/{3 + seed % 3}@{1 + seed % 3}")
    model = RandomModel(seed)
    cfg = ReCAPConfig(window=window, window_mode=mode, max_level=level, max_llm_calls=60, reminder_period=3)
    run = run_recap([model] * 60, cfg, env=env, demonstration="DEMO")
    assert run.result.end_reason in {"success", "agent_done", "call_cap", "json_failures", "step_cap"}
    # no call ever sees more than K + 2 messages, and both pins are always there
    for req in run.client.requests:
        assert len(req.messages) <= window + 2
        assert req.window_seqs[:2] == (0, 1)
    # the recursion depth equals the node's depth along the active path
    for purpose, depth, loops in model.observed:
        if purpose in REFINES:
            assert loops == depth + 1
        elif purpose in ("descend", "depth_cap"):
            assert loops == depth
        elif purpose == "task":
            assert loops == 0
    # every node's chain of parents has its depth as length
    parents = {n.node_id: n.parent_id for n in run.nodes}
    for n in run.nodes:
        chain, cur = 0, n.parent_id
        while cur is not None:
            chain, cur = chain + 1, parents[cur]
        assert chain == n.depth
        if level is not None:
            assert n.depth <= level - 1
