"""What an episode costs under each provider's prompt caching: ReCAP (pair and block windowing,
several block sizes) against ReAct, on the same trajectories.

Trajectories: the expert test double (``offline/expert``) plays Robotouille synchronous task 6
(lettuce-tomato cheeseburger) and the ALFWorld heat games, so every method takes the same
actions and only the prompts differ. Each episode's requests are recorded once per method
setting (``--profile``, default ``paper``: the released baselines' protocol, each method's
environment options as a sweep sets them, so ReAct sees ALFWorld's valid actions) and then replayed
through each provider's caching rule - the same code the fake server answers with
(:mod:`workers.llm.prompt_cache`), with the gateway's breakpoints
(:mod:`workers.llm.cache_markers`) for the provider that needs them - and priced with the
repo's price table (list prices: GPT-4o, Claude Sonnet 4.5, DeepSeek-chat). Calls follow each
other within an episode (one every ``--call-gap-s`` seconds, far inside every TTL), and
episodes never share a cache (each gets a fresh one: the pessimistic case; in a sweep,
episodes of one instance share the demonstration's prefix too).

Token counts are the documented chars / 4 estimate; the reply is the expert's JSON (a real
model writes more "think" text, which is output and not cached: the ratios below are for
input-dominated traffic, which is ReCAP's case).

    .venv/bin/python bench/cost.py [--profile paper|released] [--alfworld-limit N] [--blocks 16,32,48] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
os.environ.setdefault("LITELLM_LOCAL_MODEL_COST_MAP", "True")

from recap.llm import LLMRequest, LLMResponse  # noqa: E402
from workers.llm.cache_markers import BreakpointPlanner, mark  # noqa: E402
from workers.llm.pricing import Price, default_prices  # noqa: E402
from workers.llm.prompt_cache import PromptCache, normalize  # noqa: E402
from workers.llm.providers import provider_messages  # noqa: E402
from workers.llm.tokens import estimate_text_tokens  # noqa: E402

ROBOTOUILLE_TASK = "robotouille/synchronous/6_lettuce_tomato_cheeseburger"
#: provider -> (model in the price table, caching rule)
PROVIDERS = {
    "gpt-4o": ("gpt-4o", "openai"),
    "claude-sonnet-4.5": ("anthropic/claude-sonnet-4-5", "anthropic"),
    "deepseek-chat": ("deepseek/deepseek-chat", "deepseek"),
}
PAPER_RATIO = 118.40 / 37.89  # ReCAP / ReAct on ALFWorld in the paper (GPT-4o, no caching)


@dataclass
class Trajectory:
    instance_id: str
    arm: str
    calls: list[tuple[list[dict[str, str]], str]] = field(default_factory=list)  # (messages, reply)
    success: bool = False


class Recorder:
    """An LLM client that records each request's messages and the reply it got."""

    def __init__(self, inner: Any, trajectory: Trajectory):
        self.inner = inner
        self.trajectory = trajectory

    def complete(self, request: LLMRequest) -> LLMResponse:
        resp = self.inner.complete(request)
        self.trajectory.calls.append((provider_messages(request.messages), resp.text))
        return resp


def arms(blocks: list[int]) -> dict[str, tuple[str, dict[str, Any]]]:
    out = {"react": ("react", {}), "recap/pair": ("recap", {"window_mode": "pair"})}
    for b in blocks:
        out[f"recap/block{b}"] = ("recap", {"window_mode": "block", "window_block": b})
    return out


def record(instance_id: str, arm: str, method: str, settings: dict[str, Any], profile: str = "paper") -> Trajectory:
    from workers.envs.registry import get_benchmark, make_env
    from workers.episode_worker import EpisodeClient, build_agent
    from workers.llm.direct import LiteLLMClient
    from workers.llm.providers import DeploymentConfig

    benchmark = instance_id.split("/", 1)[0]
    traj = Trajectory(instance_id, arm)
    agent = build_agent(method, profile=profile, benchmark=benchmark, settings=settings)
    # the environment each method sees in a sweep (ALFWorld: whether the valid actions are listed)
    env = make_env(instance_id, **get_benchmark(benchmark).options_for_agent(agent.style, agent.config))
    try:
        inner = Recorder(LiteLLMClient(DeploymentConfig(model="offline/expert")), traj)
        result = agent.run(env, EpisodeClient(inner, env, sampling_seed=0, offline=True), episode_id=f"{arm}:{instance_id}")
        traj.success = bool(result.success)
    finally:
        env.close()
    return traj


@dataclass
class Bill:
    calls: int = 0
    prompt: int = 0
    cached: int = 0
    written: int = 0
    completion: int = 0
    pico: int = 0
    pico_uncached: int = 0

    def add(self, other: Bill) -> None:
        for k in self.__dataclass_fields__:
            setattr(self, k, getattr(self, k) + getattr(other, k))


def bill(traj: Trajectory, price: Price, rule: str, gap_s: float) -> Bill:
    """Replay one trajectory through a fresh cache of ``rule`` and price every call."""
    cache = PromptCache(rule)
    planner = BreakpointPlanner() if price.explicit_cache else None
    out = Bill()
    for i, (messages, reply) in enumerate(traj.calls):
        sent = mark(planner, "episode", messages) if planner is not None else messages
        o = cache.serve("model", normalize(sent), i * gap_s, reply=reply)
        completion = estimate_text_tokens(reply)
        out.calls += 1
        out.prompt += o.prompt_tokens
        out.cached += o.cached_tokens
        out.written += o.cache_write_tokens
        out.completion += completion
        out.pico += price.cost_pico(o.prompt_tokens, o.cached_tokens, completion, o.cache_write_tokens)
        out.pico_uncached += price.cost_pico(o.prompt_tokens, 0, completion)
    return out


def instances(alfworld_limit: int | None) -> dict[str, list[str]]:
    from workers.envs.registry import get_benchmark

    robo = [i for i in get_benchmark("robotouille").list_instances(None) if i.startswith(ROBOTOUILLE_TASK + "@")]
    heat = [i for i in get_benchmark("alfworld").list_instances(None) if i.startswith("alfworld/heat/")]
    return {"robotouille task 6": robo, "alfworld heat": heat[:alfworld_limit] if alfworld_limit else heat}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--blocks", default="16,32,48", help="block sizes of block windowing (K = 64)")
    p.add_argument("--alfworld-limit", type=int, help="the first N heat games only (default: all)")
    p.add_argument("--robotouille-limit", type=int, help="the first N task-6 instances only (default: all)")
    p.add_argument("--call-gap-s", type=float, default=5.0, help="seconds between an episode's calls")
    p.add_argument("--json", help="write the table as JSON here")
    p.add_argument("--profile", default="paper", choices=("paper", "released"), help="the methods' profile")
    args = p.parse_args(argv)
    blocks = [int(b) for b in args.blocks.split(",") if b.strip()]
    prices = default_prices()
    settings = arms(blocks)
    t0 = time.perf_counter()
    groups = instances(args.alfworld_limit)
    if args.robotouille_limit:
        groups["robotouille task 6"] = groups["robotouille task 6"][: args.robotouille_limit]
    rows = []
    for group, ids in groups.items():
        if not ids:
            print(f"{group}: no instances found (is the benchmark data there? `recap data check`)")
            continue
        trajs = {arm: [record(i, arm, m, s, args.profile) for i in ids] for arm, (m, s) in settings.items()}
        steps = {arm: sum(len(t.calls) for t in ts) / len(ts) for arm, ts in trajs.items()}
        print(
            f"\n{group}: {len(ids)} episodes; calls/episode "
            + ", ".join(f"{a} {n:.1f}" for a, n in steps.items())
            + f"; solved {sum(t.success for t in trajs['recap/pair'])}/{len(ids)} ({time.perf_counter() - t0:.0f}s)"
        )
        print(
            f"{'provider':<18} {'arm':<14} {'prompt tok/ep':>13} {'cached':>7} {'written':>7} "
            f"{'$/ep':>9} {'$/ep no cache':>13} {'vs ReAct':>8} {'no cache':>8}"
        )
        for provider, (model, rule) in PROVIDERS.items():
            price = prices.get(model)
            bills = {}
            for arm, ts in trajs.items():
                total = Bill()
                for t in ts:
                    total.add(bill(t, price, rule, args.call_gap_s))
                bills[arm] = total
            react = bills["react"]
            for arm, b in bills.items():
                n = len(ids)
                row = {
                    "group": group,
                    "provider": provider,
                    "model": model,
                    "rule": rule,
                    "arm": arm,
                    "episodes": n,
                    "calls_per_episode": b.calls / n,
                    "prompt_tokens_per_episode": b.prompt / n,
                    "cached_share": b.cached / b.prompt if b.prompt else 0.0,
                    "written_share": b.written / b.prompt if b.prompt else 0.0,
                    "usd_per_episode": b.pico / n / 1e12,
                    "usd_per_episode_uncached": b.pico_uncached / n / 1e12,
                    "ratio_vs_react": b.pico / react.pico if react.pico else None,
                    "ratio_vs_react_uncached": b.pico_uncached / react.pico_uncached if react.pico_uncached else None,
                }
                rows.append(row)
                print(
                    f"{provider:<18} {arm:<14} {row['prompt_tokens_per_episode']:>13,.0f} "
                    f"{row['cached_share']:>7.1%} {row['written_share']:>7.1%} "
                    f"{row['usd_per_episode']:>9.4f} {row['usd_per_episode_uncached']:>13.4f} "
                    f"{row['ratio_vs_react']:>7.2f}x {row['ratio_vs_react_uncached']:>7.2f}x"
                )
    print(f"\npaper (ALFWorld, GPT-4o, no caching): ReCAP / ReAct = $118.40 / $37.89 = {PAPER_RATIO:.2f}x")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
