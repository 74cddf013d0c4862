"""``python -m workers.llm.offline.fake_server``: the fake server on its own, until killed."""

from __future__ import annotations

import argparse
import asyncio

from workers.llm.offline.fake_server.config import FakeServerConfig
from workers.llm.offline.fake_server.faults import DEFAULT_REPLY, FAULT_MODES
from workers.llm.offline.fake_server.server import FakeServer
from workers.llm.prompt_cache import RULES


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(description="TEST DOUBLE: loopback OpenAI-compatible chat server")
    p.add_argument("--port", type=int, default=0, help="0 = a random free port")
    p.add_argument("--rpm", type=int)
    p.add_argument("--tpm", type=int)
    p.add_argument("--window-s", type=float, default=60.0)
    p.add_argument("--latency-s", type=float, default=0.0)
    p.add_argument("--latency-jitter-s", type=float, default=0.0)
    p.add_argument("--reply", default=DEFAULT_REPLY)
    p.add_argument("--max-context-tokens", type=int)
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="MODE=RATE",
        help=f"inject a fault at random; modes: {', '.join(FAULT_MODES)}",
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--require-api-key")
    p.add_argument(
        "--cache-rule", default="lcp", choices=RULES, help="prompt-cache rule of models without --model-cache-rule (default lcp)"
    )
    p.add_argument(
        "--model-cache-rule",
        action="append",
        default=[],
        metavar="MODEL=RULE",
        help="the prompt-cache rule of one model name (repeatable)",
    )
    p.add_argument("--cache-ttl-s", type=float, help="seconds an unused cache entry lives (default: the rule's)")
    return p


def _config(args: argparse.Namespace) -> FakeServerConfig:
    """The server's settings from the command line (``MODEL=RULE`` and ``MODE=RATE`` pairs split)."""
    rules = {}
    for item in args.model_cache_rule:
        name, _, rule = item.partition("=")
        rules[name] = rule
    faults = {}
    for item in args.fault:
        mode, _, rate = item.partition("=")
        faults[mode] = float(rate)
    return FakeServerConfig(
        rpm=args.rpm,
        tpm=args.tpm,
        window_s=args.window_s,
        latency_s=args.latency_s,
        latency_jitter_s=args.latency_jitter_s,
        reply=args.reply,
        max_context_tokens=args.max_context_tokens,
        fault_rates=faults,
        seed=args.seed,
        require_api_key=args.require_api_key,
        cache_rule=args.cache_rule,
        cache_rules=rules,
        cache_ttl_s=args.cache_ttl_s,
    )


def main(argv: list[str] | None = None) -> None:
    """``python -m workers.llm.offline.fake_server``: serve until killed, printing the port."""
    args = _parser().parse_args(argv)
    server = FakeServer(_config(args))

    async def serve() -> None:
        url = await server.start(args.port)
        print(f"fake server listening on {url}", flush=True)
        await asyncio.Event().wait()

    try:
        asyncio.run(serve())
    except KeyboardInterrupt:
        pass


if __name__ == "__main__":
    main()
