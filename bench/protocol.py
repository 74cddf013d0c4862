"""The protocol's sizes per method x benchmark: what each method pins, how long its longest reply
can be, and whether its call cap lets it use its step budget.

For every method and benchmark this prints

* the one-shot demonstration in tokens (gpt-4o tokenizer): with every observation shown
  (``demo_observations: all``, before issue 12) and under the ``paper`` profile;
* the longest *expert* reply of any instance in the method's reply format, against the
  method's output cap (``max_tokens``). An expert reply is the instance's expert plan from the
  start written as the method would write it: CoT/Standard list every action, ReCAP's root lists
  every action as a subtask (its worst case), ReAct/Act/ADaPT name one action. Its think is the
  longest think of that method's demonstration (real text of the size the model is shown);
* the largest step cap of the benchmark and the call cap each method derives from it.

    .venv/bin/python bench/protocol.py [--alfworld-limit N] [--json out.json]

Data: ``ROBOTOUILLE_DATA`` / ``ALFWORLD_DATA`` (default ``../shared/data/...``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")
_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
os.environ.setdefault("ROBOTOUILLE_DATA", os.path.join(_ROOT, "..", "shared", "data", "robotouille"))
os.environ.setdefault("ALFWORLD_DATA", os.path.join(_ROOT, "..", "shared", "data", "alfworld"))

from recap.methods import METHODS, make_agent  # noqa: E402
from workers.envs.registry import get_benchmark, make_env  # noqa: E402
from workers.llm.tokens import count_text_tokens  # noqa: E402

MODEL = "gpt-4o"
#: the methods the paper runs on each benchmark (others are shown when they can render a demo)
BENCHMARKS = ("robotouille", "alfworld")


def tokens(text: str) -> int:
    return count_text_tokens(MODEL, text).tokens


def longest_think(replies: list[dict]) -> str:
    thinks = [str(r.get("think", "")) for r in replies if isinstance(r, dict)]
    return max(thinks, key=len, default="")


def expert_reply(method: str, plan: list[str], think: str) -> str:
    """The instance's expert plan in ``method``'s reply format (see the module docstring)."""
    longest_action = max(plan, key=len) if plan else ""
    if method in ("cot", "standard"):
        reply = {"think": think, "actions": plan}
    elif method == "recap":
        reply = {"think": think, "subtasks": plan}
    elif method == "adapt":
        reply = {"think": think, "action": longest_action}
    else:
        reply = {"think": think, "action": longest_action}
    if method in ("act", "standard"):
        reply.pop("think")
    return json.dumps(reply)


def instance_plans(benchmark: str, limit: int | None) -> tuple[list[tuple[str, int, list[str]]], object]:
    """(instance id, step cap, expert plan) per instance, and one env for the demonstration."""
    ids = get_benchmark(benchmark).list_instances(None)
    if limit:
        ids = ids[:limit]
    out = []
    demo_env = None
    for iid in ids:
        env = make_env(iid)
        try:
            env.reset()
            out.append((iid, int(env.max_steps), list(env.expert_plan() or [])))
        finally:
            if demo_env is None:
                demo_env = env
            else:
                env.close()
    return out, demo_env


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--alfworld-limit", type=int, default=None, help="first N ALFWorld games only (all 134 by default)")
    ap.add_argument("--json", default=None, help="also write the rows as JSON")
    args = ap.parse_args()
    rows = []
    for benchmark in BENCHMARKS:
        t0 = time.perf_counter()
        try:
            plans, env = instance_plans(benchmark, args.alfworld_limit if benchmark == "alfworld" else None)
        except Exception as exc:  # a benchmark without data or package: say so, go on
            print(f"{benchmark}: skipped ({type(exc).__name__}: {exc})")
            continue
        longest_plan = max(plans, key=lambda p: len(json.dumps(p[2])))
        max_steps = max(p[1] for p in plans)
        demo = env.demonstration()
        print(
            f"{benchmark}: {len(plans)} instances in {time.perf_counter() - t0:.1f}s; longest expert plan "
            f"{len(longest_plan[2])} actions ({longest_plan[0]}); largest step cap {max_steps}"
        )
        for method in METHODS:
            paper = make_agent(method, profile="paper", benchmark=get_benchmark(benchmark))
            every = make_agent(method, profile="paper", benchmark=get_benchmark(benchmark), demo_observations="all")
            try:
                demo_all = tokens(every.demonstration_text(env) or "")
                demo_paper = tokens(paper.demonstration_text(env) or "")
            except Exception as exc:
                print(f"  {method}: no demonstration ({type(exc).__name__}: {exc})")
                continue
            replies = list((demo.replies.get(paper.style) if demo else None) or [])
            think = longest_think(replies)
            reply_tokens = max(tokens(expert_reply(method, plan, think)) for _, _, plan in plans)
            cap = paper.config.max_tokens
            rows.append(
                {
                    "benchmark": benchmark,
                    "method": method,
                    "demo_tokens_all_obs": demo_all,
                    "demo_tokens_paper": demo_paper,
                    "longest_expert_reply_tokens": reply_tokens,
                    "max_tokens": cap,
                    "output_headroom": round(cap / reply_tokens, 2) if cap else None,
                    "max_step_cap": max_steps,
                    "call_cap": paper.call_cap(max_steps),
                    "call_cap_per_step": round(paper.call_cap(max_steps) / max_steps, 2),
                }
            )
        env.close()
    cols = [
        "benchmark",
        "method",
        "demo_tokens_all_obs",
        "demo_tokens_paper",
        "longest_expert_reply_tokens",
        "max_tokens",
        "output_headroom",
        "max_step_cap",
        "call_cap",
        "call_cap_per_step",
    ]
    widths = {c: max(len(c), *(len(str(r[c])) for r in rows)) if rows else len(c) for c in cols}
    print("  ".join(c.ljust(widths[c]) for c in cols))
    for r in rows:
        print("  ".join(str(r[c]).ljust(widths[c]) for c in cols))
    short = [r for r in rows if r["max_tokens"] and r["longest_expert_reply_tokens"] > r["max_tokens"]]
    print(
        f"output caps below the longest expert reply: {len(short)}"
        + "".join(f"\n  {r['method']} on {r['benchmark']}" for r in short)
    )
    need = {m: max((r["longest_expert_reply_tokens"] for r in rows if r["method"] == m), default=0) for m in METHODS}
    print(
        "suggested caps (2 x the longest expert reply, rounded up to 256): "
        + ", ".join(f"{m} {256 * math.ceil(2 * n / 256)}" for m, n in need.items() if n)
    )
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
