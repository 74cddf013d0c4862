"""Prompt size along episodes of growing length: ReCAP's window keeps it flat, a flat ReAct
history grows; and, per windowing mode, the share of each prompt that repeats the previous
prompt's prefix (what a provider's prompt cache can bill at the cached price).

The episode is a long, regular blocksworld chore (pick a block up and put it down N/2 times)
driven by scripted models, so only the context management differs between methods. ReCAP's
root plans a bounded horizon (the next three rounds), as a real plan of subgoals would.

    .venv/bin/python bench/prompt_bound.py [--lengths 25,50,100,200,400] [--window 64]
"""

from __future__ import annotations

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

from recap.blocksworld import BlocksworldEnv  # noqa: E402
from recap.llm import LLMRequest  # noqa: E402
from recap.methods import make_agent  # noqa: E402
from recap.scripted import ScriptedClient, estimate_tokens  # noqa: E402


def chore_env(steps: int) -> BlocksworldEnv:
    env = BlocksworldEnv([["A", "C"], ["B"]], ["A", "B", "C"], instance_id="blocksworld/chore", demo=False)
    env.max_steps = steps
    return env


def recap_model(cycles: int):
    """Root plans a bounded horizon (the next three rounds), each round is two actions."""
    state = {"done": 0}

    def rounds() -> list[str]:
        return [f"round {i}" for i in range(state["done"] + 1, min(cycles, state["done"] + 3) + 1)]

    def reply(req: LLMRequest) -> str:
        h = req.hints
        if h["purpose"] == "task":
            subs = rounds()
        elif h["purpose"] == "descend":
            subs = ["pick up B", "put down B"]
        elif h["depth"] == 0:
            state["done"] += 1
            subs = rounds()
        else:
            subs = h["remaining"]
        return json.dumps({"think": f"Working on {h['task']}; {len(subs)} subtasks planned next.", "subtasks": subs})

    return reply


def react_model(req: LLMRequest) -> str:
    action = "pick up B" if "pick up B" in (req.hints["valid_actions"] or []) else "put down B"
    return json.dumps({"think": "Keep cycling block B between the table and the gripper.", "action": action})


def prompt_tokens(req: LLMRequest) -> int:
    return sum(estimate_tokens(m.content) for m in req.messages)


def cacheable_share(requests: list[LLMRequest]) -> float:
    """Mean over calls of (characters in messages identical to the previous prompt's prefix) /
    (characters in the prompt)."""
    shares = []
    for prev, cur in zip(requests, requests[1:]):
        same = 0
        for a, b in zip(prev.messages, cur.messages):
            if a != b:
                break
            same += len(b.content)
        total = sum(len(m.content) for m in cur.messages)
        shares.append(same / total if total else 0.0)
    return sum(shares) / len(shares) if shares else 0.0


def run(method: str, steps: int, window: int, mode: str) -> list[LLMRequest]:
    if method == "recap":
        agent = make_agent("recap", window=window, window_mode=mode, max_llm_calls=100_000)
        client = ScriptedClient([recap_model(steps // 2)] * (steps * 3))
    else:
        agent = make_agent("react", window=window, window_mode=mode, max_llm_calls=100_000)
        client = ScriptedClient([react_model] * (steps + 5))
    agent.run(chore_env(steps), client, demonstration="(demonstration omitted in this benchmark)")
    return client.requests


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="25,50,100,200,400")
    ap.add_argument("--window", type=int, default=64)
    args = ap.parse_args()
    lengths = [int(x) for x in args.lengths.split(",")]
    K = args.window
    variants = [
        (f"ReCAP K={K} pair", "recap", K, "pair"),
        (f"ReCAP K={K} block", "recap", K, "block"),
        (f"ReAct K={K} pair", "react", K, "pair"),
        ("ReAct full history", "react", 10**9, "pair"),
    ]
    print(f"Max prompt size per call (estimated tokens = chars/4) vs episode length (environment steps), window K={K} messages")
    print(f"{'variant':<22}" + "".join(f"{n:>10}" for n in lengths) + f"{'calls@max':>11}")
    results: dict[str, dict[int, list[LLMRequest]]] = {}
    for label, method, window, mode in variants:
        row = []
        results[label] = {}
        for n in lengths:
            reqs = run(method, n, window, mode)
            results[label][n] = reqs
            row.append(max(prompt_tokens(r) for r in reqs))
        print(f"{label:<22}" + "".join(f"{v:>10}" for v in row) + f"{len(results[label][lengths[-1]]):>11}")
    n = lengths[-1]
    print(f"\nPrompt size along the {n}-step episode (every {max(1, len(results[variants[0][0]][n]) // 8)}th call):")
    for label, *_ in variants:
        reqs = results[label][n]
        stride = max(1, len(reqs) // 8)
        print(f"{label:<22}" + " ".join(f"{prompt_tokens(r):>6}" for r in reqs[::stride]))
    recap_growth = max(prompt_tokens(r) for r in results[variants[0][0]][lengths[-1]]) / max(
        prompt_tokens(r) for r in results[variants[0][0]][lengths[-2]]
    )
    react_growth = max(prompt_tokens(r) for r in results[variants[3][0]][lengths[-1]]) / max(
        prompt_tokens(r) for r in results[variants[3][0]][lengths[-2]]
    )
    print(
        f"\nGrowth of the max prompt from {lengths[-2]} to {lengths[-1]} steps: ReCAP x{recap_growth:.2f}, ReAct full history x{react_growth:.2f}"
    )
    print(f"\nCacheable share (mean fraction of each prompt identical to the previous prompt's prefix), {n}-step episode:")
    for label, *_ in variants:
        print(f"{label:<22}{cacheable_share(results[label][n]):>8.1%}")


if __name__ == "__main__":
    main()
