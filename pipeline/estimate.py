"""``recap estimate SPEC``: units, expected calls, tokens and a cost range before spending anything.

The estimate is deliberately a *range* from a simple model of each method, not a promise:

* calls per episode: each method's agent class says what to assume
  (``Agent.estimate_calls_per_step``, ``Agent.one_shot``): ReCAP makes about one call per
  environment step when its plans hold and up to ~2.5 per allowed step when it re-plans;
  ReAct/Act one per step; CoT/Standard one plan call (plus repairs); ADaPT up to ~3 per step.
  Both ends are clipped to the per-episode call limit.
* prompt tokens per call: the pinned prompt (rules, demonstration, first observation - measured
  on the instance itself, at 4 characters per token) plus the sliding window, which fills with
  one observation and one reply per step up to its size K.
* cost: those tokens at the model's price (sweep override, else the repo price table); the low
  end bills half of each prompt at the cached-input price. A model the sweep serves itself
  (``models[].serve``) is priced by the replica-hours its output tokens take at its tokens/s -
  ``serve.tokens_per_s`` in the sweep, or measured by ``recap estimate --probe``
  (:mod:`pipeline.serving.throughput`); the source is printed with the figure.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from rich.markup import escape

from pipeline.serving.engines import serve_plan
from pipeline.serving.throughput import Throughput, efficiency, serving_cost, sweep_throughput
from pipeline.spec import SweepSpec
from pipeline.summary import model_label
from pipeline.tables import Col, print_fitted
from pipeline.units import Plan
from recap.agent import Agent
from recap.methods import METHODS, method_classes
from recap.plural import count
from workers.envs.registry import get_benchmark, make_env
from workers.llm.pricing import PriceError, resolve_price

COMPLETION_TOKENS = (60, 250)
DEFAULT_OPTIMAL = 20


def _tokens(text: str) -> int:
    return max(1, (len(text) + 3) // 4)


@dataclass
class InstanceShape:
    """What the estimate needs of one instance: optimal and allowed steps, the tokens of the pinned
    prompt (rules, first observation, demonstration) and of one observation. ``measured`` False:
    defaults, because the instance could not be built here."""

    optimal: int
    max_steps: int
    pinned_tokens: int
    obs_tokens: int
    measured: bool


def measure_instance(instance_id: str, step_multiplier: float, options: dict[str, Any]) -> InstanceShape:
    """The :class:`InstanceShape` of ``instance_id`` (4 characters per token): from the figures its
    benchmark gives without playing it (:meth:`~workers.envs.registry.Benchmark.estimate_figures`:
    ALFWorld's games take seconds each to build, a coding task would open a container), else by
    making and resetting it once. Any failure (data missing, an optional package absent) gives
    default figures with ``measured=False``, so one instance never fails the estimate."""
    try:
        figures = get_benchmark(instance_id.split("/", 1)[0]).estimate_figures(instance_id, options)
        if figures is not None:
            rules, obs = _tokens(figures.rules), max(1, (figures.observation_chars + 3) // 4)
            demo = 3 * (rules + obs) if figures.demonstration else 0
            optimal = figures.optimal_steps or DEFAULT_OPTIMAL
            return InstanceShape(optimal, figures.max_steps, rules + obs + demo + 200, obs, True)
        env = make_env(instance_id, step_multiplier=step_multiplier, **options)
        try:
            r = env.reset()
            rules_text = env.rules()
            optimal = env.optimal_steps or DEFAULT_OPTIMAL
            obs = _tokens(r.observation)
            demo = 3 * (_tokens(rules_text) + obs) if env.demonstration() is not None else 0
            return InstanceShape(optimal, env.max_steps, _tokens(rules_text) + obs + demo + 200, obs, True)
        finally:
            env.close()
    except Exception:
        return InstanceShape(DEFAULT_OPTIMAL, math.ceil(DEFAULT_OPTIMAL * step_multiplier), 3000, 300, False)


@dataclass
class Range:
    """A low-high interval that sums: the calls, tokens or dollars of an estimate."""

    low: float = 0.0
    high: float = 0.0

    def add(self, low: float, high: float) -> None:
        self.low += low
        self.high += high


@dataclass
class GroupEstimate:
    """The estimate of one (method, model) pair: its units and the summed ranges of calls, tokens
    and dollars (``cost`` None: the model has no price)."""

    method: str
    model: str
    test_double: bool
    units: int = 0
    calls: Range = None  # type: ignore[assignment]
    tokens: Range = None  # type: ignore[assignment]
    cost: Range | None = None
    #: the output tokens of ``tokens`` (what a served model's replica-hours are priced by)
    output: Range = None  # type: ignore[assignment]
    #: a served model: the tokens/s its cost was priced at (None: neither given nor probed)
    throughput: Throughput | None = None

    def __post_init__(self) -> None:
        self.calls, self.tokens, self.output = Range(), Range(), Range()


def call_shape(method: str) -> tuple[bool, tuple[float, float]]:
    """(one call per episode?, (low, high) calls per allowed step) as the method's agent class
    declares them; a name nothing registers gets the base class's assumption."""
    agent_cls = method_classes(method)[0] if method in METHODS else Agent
    return agent_cls.one_shot, agent_cls.estimate_calls_per_step


def _price(spec: SweepSpec, model_label: str) -> Any:
    m = spec.model(model_label)
    try:
        return resolve_price(m.model, m.token_prices())
    except PriceError:
        return None


def _prompt_total(calls: float, shape: InstanceShape, window: int) -> float:
    """Prompt tokens over ``calls`` calls: call i sees the pinned prompt and min(window, 2i)
    messages of about an observation plus half the completion budget each."""
    per_msg = shape.obs_tokens + COMPLETION_TOKENS[1] // 2
    full = max(0.0, calls - window / 2)
    ramp = min(calls, window / 2)
    return calls * shape.pinned_tokens + per_msg * (ramp * ramp + full * window)


def instances_to_measure(plan: Plan) -> int:
    """How many (instance, step multiplier) pairs :func:`estimate` measures: the progress line's count."""
    return len({(u.instance_id, float(u.step_multiplier)) for u in plan.units})


def estimate(plan: Plan, measured: dict[str, Throughput] | None = None) -> list[GroupEstimate]:
    """One :class:`GroupEstimate` per (method label, model label) of the plan, in the order first
    seen. Calls come from the method's call shape and the instance's steps, clipped to
    ``max_llm_calls``; tokens from the sliding-window model; dollars from the model's price, or
    for a served model from its replica-hours at the tokens/s of the sweep or of ``measured``
    (model label -> what a probe measured)."""
    spec = plan.spec
    throughput = {**(measured or {}), **sweep_throughput(spec)}
    # keyed by the step multiplier too: methods of one sweep may run an instance at different caps
    shapes: dict[tuple[str, float], InstanceShape] = {}
    groups: dict[tuple[str, str], GroupEstimate] = {}
    for u in plan.units:
        key = (u.instance_id, float(u.step_multiplier))
        if key not in shapes:
            shapes[key] = measure_instance(u.instance_id, u.step_multiplier, dict(u.env_options))
        shape = shapes[key]
        cfg = json.loads(u.method_config)
        max_calls = int(cfg.get("max_llm_calls") or 10**9)  # None: derived from the step cap (c_high below)
        window = int(cfg.get("window") or 64)
        # ReAct/Act's history setting narrows or lifts the window (recap.baselines.react): the
        # released Act keeps everything, Robotouille's "last" ablation two messages
        history = cfg.get("history")
        if history == "all":
            window = 10**9
        elif history == "last":
            window = 2
        one_shot, (lo, hi) = call_shape(u.method)
        if one_shot:
            c_low, c_high = 1.0, float(min(max_calls, 1 + int(cfg.get("max_json_repairs", 3))))
        else:
            c_low = min(max_calls, max(1.0, shape.optimal * lo + 1))
            c_high = min(max_calls, max(c_low, shape.max_steps * hi + 1))
        p_low, p_high = _prompt_total(c_low, shape, window), _prompt_total(c_high, shape, window)
        o_low, o_high = c_low * COMPLETION_TOKENS[0], c_high * COMPLETION_TOKENS[1]
        g = groups.setdefault(
            (u.method_label, u.model_label), GroupEstimate(u.method_label, u.model_label, u.model.startswith("offline/"))
        )
        g.units += 1
        g.calls.add(c_low, c_high)
        g.tokens.add(p_low + o_low, p_high + o_high)
        g.output.add(o_low, o_high)
        price = _price(spec, u.model_label)
        if spec.model(u.model_label).serve is not None:
            continue  # priced by its replica-hours below
        if price is not None:
            r_in, r_cached, r_out = (x / 1e12 for x in price.rates())
            low = p_low / 2 * r_cached + p_low / 2 * r_in + o_low * r_out
            high = p_high * r_in + o_high * r_out
            if g.cost is None:
                g.cost = Range()
            g.cost.add(low, high)
    for g in groups.values():
        m = spec.model(g.model)
        if m.serve is not None and g.model in throughput:
            splan, g.throughput = serve_plan(m), throughput[g.model]
            low_cost = serving_cost(g.output.low, splan, g.throughput.tokens_per_s, spec.workers)
            high_cost = serving_cost(g.output.high, splan, g.throughput.tokens_per_s, spec.workers)
            g.cost = Range(low_cost.usd, high_cost.usd)
    return list(groups.values())


def render(plan: Plan, groups: list[GroupEstimate], needs: Sequence[str], console: Any) -> None:
    """Print the estimate on ``console`` (a rich Console): one row per group, the run's totals,
    whether the run cap fits the cost range, and what a run still needs on this machine
    (``needs``: images, a daemon; ``recap run`` refuses until they are here)."""

    cols = (
        Col("method", "left"),
        Col("model", "left"),
        Col("units", drop=3),
        Col("calls", drop=2),
        Col("tokens", drop=1),
        Col("cost $", drop=4),
    )
    rows: list[list[str]] = []
    total_cost = Range()
    unknown = False
    for g in groups:
        cost = f"{g.cost.low:.2f} - {g.cost.high:.2f}" if g.cost else "no price"
        if g.cost:
            total_cost.add(g.cost.low, g.cost.high)
        else:
            unknown = True
        rows.append(
            [
                g.method,
                model_label(g.model, g.test_double),
                str(g.units),
                f"{g.calls.low:,.0f} - {g.calls.high:,.0f}",
                f"{g.tokens.low:,.0f} - {g.tokens.high:,.0f}",
                cost,
            ]
        )
    print_fitted(console, f"estimate for run {plan.spec.run}: {count(len(plan.units), 'unit')}", cols, rows)
    calls = sum(g.calls.low for g in groups), sum(g.calls.high for g in groups)
    line = f"total: {count(len(plan.units), 'unit')}, {calls[0]:,.0f} - {calls[1]:,.0f} calls, ${total_cost.low:.2f} - ${total_cost.high:.2f}"
    if unknown:
        line += " (plus models without a price)"
    console.print(line)
    cap = plan.spec.run_cap_usd
    if cap is not None:
        verdict = "fits" if total_cost.high <= cap else ("may be reached" if total_cost.low <= cap else "will be reached")
        console.print(f"run cap ${cap:.2f}: {verdict}")
    for label, t, splan in _served_lines(plan.spec, groups):
        console.print(
            escape(
                f"{label}: served, {t.tokens_per_s:,.1f} output tokens/s a replica ({t.source}), {splan.replicas} x "
                f"${splan.usd_per_replica_hour:g}/replica-hour, efficiency {efficiency(splan, plan.spec.workers):.2f}"
            ),
            soft_wrap=True,
        )
    for label in _served_unpriced(plan.spec, groups):
        console.print(
            escape(f"{label}: served, no tokens/s: give serve.tokens_per_s or run recap estimate --probe"), soft_wrap=True
        )
    if needs:  # one per line, never wrapped: each is a phrase to read (and grep) whole
        console.print("a run still needs (recap run refuses until then):", soft_wrap=True)
        for need in needs:
            console.print(escape(f"  - {need}"), soft_wrap=True)


def _served_lines(spec: SweepSpec, groups: list[GroupEstimate]) -> list[tuple[str, Throughput, Any]]:
    """(label, tokens/s, plan) of each served model priced by its tokens/s, once each."""
    seen: dict[str, tuple[str, Throughput, Any]] = {}
    for g in groups:
        if g.throughput is not None and g.model not in seen:
            seen[g.model] = (g.model, g.throughput, serve_plan(spec.model(g.model)))
    return list(seen.values())


def _served_unpriced(spec: SweepSpec, groups: list[GroupEstimate]) -> list[str]:
    """The served models with no tokens/s to price them by."""
    return list(dict.fromkeys(g.model for g in groups if g.throughput is None and spec.model(g.model).serve is not None))
