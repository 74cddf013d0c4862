"""The driver's roles, each alone: the cap policy, the terminal row, the in-process worker
pool, the sink channel's direct writes, and the typed seams (refusal, resolved settings)."""

from __future__ import annotations

import json
import threading
import time

import pytest

from pipeline.backend import Spend
from pipeline.cap_policy import CapPolicy
from pipeline.episode_rows import episode_record
from pipeline.events import EventBuffer
from pipeline.resume import AttemptSpend, Pending
from pipeline.sink_channel import SinkChannel
from pipeline.spec import parse_spec
from pipeline.units import expand
from pipeline.worker_pool import InProcessWorkerPool
from schemas.outcomes import BudgetRefusal, Crash, EnvFacts, EpisodeOutcome, EpisodeResult, UnitWork
from schemas.parts import read_table
from schemas.records import EpisodeRecord
from workers.envs.registry import get_benchmark

SPEC = """run: roles
output: {out}
run_cap_usd: 5.0
models:
  - {{label: small, model: offline/expert, cap_usd: 1.0}}
  - {{label: big, model: offline/random}}
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, instances: [blocksworld/3@1]}}]
"""


@pytest.fixture
def spec(tmp_path):
    return parse_spec(SPEC.format(out=tmp_path / "run"), "sweep.yaml")


def _events(buf: EventBuffer) -> list[tuple[str, dict]]:
    return [(e.kind, json.loads(e.detail)) for e in buf.drain()]


# -- the cap policy -----------------------------------------------------------------------------
def test_cap_policy_stops_a_model_at_its_cap_and_the_run_at_the_run_cap(spec):
    buf = EventBuffer()
    caps = CapPolicy(spec, buf.add)
    caps.check(Spend(0.99, {"small": 0.99}))
    assert caps.allows("small") and caps.allows("big") and caps.stopped is None and not buf
    caps.check(Spend(1.0, {"small": 1.0}))
    assert not caps.allows("small") and caps.allows("big") and caps.stopped == "small capped"
    caps.check(Spend(5.0, {"small": 1.0, "big": 4.0}))
    assert not caps.allows("big") and caps.stopped == "run cap $5.00 reached"
    caps.check(Spend(6.0, {"small": 1.0, "big": 5.0}))  # each stop is recorded once
    assert _events(buf) == [
        ("model_cap_reached", {"model": "small", "reason": "model cap $1.00 of small reached"}),
        ("run_cap_reached", {"reason": "run cap $5.00 reached"}),
    ]


def test_a_typed_refusal_stops_the_run_or_only_the_model_it_names(spec):
    pico = 10**12
    buf = EventBuffer()
    caps = CapPolicy(spec, buf.add)
    model_refusal = BudgetRefusal("model", "offline/expert", 1 * pico, 9 * pico // 10, pico // 8)
    caps.on_refusal("small", model_refusal, model_refusal.message, Spend(0.5, {"small": 0.5}))
    assert (caps.allows("small"), caps.allows("big"), caps.run_stopped) == (False, True, None)
    # a refusal for the run's cap stops everything, even coming from a capped model
    caps.on_refusal("small", BudgetRefusal("run", "offline/expert", 5 * pico, 5 * pico, 1), "x", Spend(4.25, {}))
    # no spend figure in the line: the one printed beside it is the ledger journal's (class 5 of #24)
    assert caps.run_stopped == "run cap $5.00 reached" and not caps.allows("big")
    # a model without a cap of its own: whatever refused it is the run's budget
    caps2 = CapPolicy(spec, EventBuffer().add)
    caps2.on_refusal("big", BudgetRefusal("unpriced", "offline/random"), "no price", Spend())
    assert caps2.run_stopped == "run cap $5.00 reached"
    assert (
        model_refusal.message == "offline/expert budget: committed $0.900000 + this call's worst case $0.125000 > cap $1.000000"
    )
    assert BudgetRefusal.from_dict(model_refusal.to_dict()) == model_refusal
    with pytest.raises(ValueError, match="unknown refusal scope 'team'"):
        BudgetRefusal("team", "m")  # type: ignore[arg-type]


def test_a_provider_stopped_for_its_usage_stops_only_its_model_even_without_a_cap(spec):
    """A ``usage`` refusal (the gateway stopped calling a provider that kept reporting impossible
    usage) stops that model's units only - also a model without a cap of its own, which a budget
    refusal would have stopped the whole run for - with one ``model_stopped`` event."""
    buf = EventBuffer()
    caps = CapPolicy(spec, buf.add)
    lying = BudgetRefusal("usage", "big", rejected=3)
    assert BudgetRefusal.from_dict(lying.to_dict()) == lying
    why = "big stopped: big: provider usage rejected as impossible in 3 replies (each charged at its worst case); no more calls to it this session"
    caps.on_refusal("big", lying, lying.message, Spend(0.1, {"big": 0.1}))
    caps.on_refusal("big", lying, lying.message, Spend(0.1, {"big": 0.1}))  # recorded once
    assert (caps.allows("big"), caps.allows("small"), caps.run_stopped, caps.stopped) == (False, True, None, why)
    caps.check(Spend(1.0, {"small": 1.0}))
    assert caps.stopped == f"small capped; {why}"
    assert _events(buf) == [
        ("model_stopped", {"model": "big", "reason": why}),
        ("model_cap_reached", {"model": "small", "reason": "model cap $1.00 of small reached"}),
    ]


def test_the_ledger_answers_with_the_cap_that_refused(tmp_path):
    from workers.gateway.ledger import BudgetLedger

    pico = 10**12
    ledger = BudgetLedger(tmp_path, run_cap_usd=1.0, model_caps_usd={"m": 0.5}, fsync=False)
    assert ledger.reserve("k1", "m", 4 * pico // 10)["status"] == "reserved"
    ans = ledger.reserve("k2", "m", 2 * pico // 10)
    assert ans == {
        "status": "refused",
        "refusal": {
            "scope": "model",
            "model": "m",
            "cap_pico": pico // 2,
            "committed_pico": 4 * pico // 10,
            "worst_pico": 2 * pico // 10,
        },
        "message": "m budget: committed $0.400000 + this call's worst case $0.200000 > cap $0.500000",
    }
    ans = ledger.reserve("k3", "n", 7 * pico // 10)
    assert (ans["refusal"]["scope"], ans["message"]) == (
        "run",
        "run budget: committed $0.400000 + this call's worst case $0.700000 > cap $1.000000",
    )
    assert ledger.reserve("k4", "m", None)["refusal"] == {
        "scope": "unpriced",
        "model": "m",
        "cap_pico": None,
        "committed_pico": 0,
        "worst_pico": None,
    }
    ledger.close()


# -- the terminal row ---------------------------------------------------------------------------
@pytest.fixture
def unit(spec):
    return expand(spec).units[0]


def _outcome(unit, result=None, crash=None, env=None):
    return EpisodeOutcome(
        unit_id=unit.unit_id,
        attempt=1,
        episode_id=f"{unit.unit_id}-1",
        worker_id="w7",
        pid=1,
        started_at=100.0,
        env=env or EnvFacts("blocksworld", "3", "3@1", 6, 12),
        model=unit.model,
        test_double=True,
        result=result,
        crash=crash,
        ended_at=103.5,
        wall_s=3.5,
    )


def test_the_row_of_an_episode_that_ended(unit):
    res = EpisodeResult(
        "success", True, 6, 7, prompt_tokens=700, cached_prompt_tokens=128, completion_tokens=70, cost_usd=0.25, max_depth=2
    )
    rec = episode_record(unit, 1, _outcome(unit, res))
    assert isinstance(rec, EpisodeRecord)
    assert (
        rec.episode_id,
        rec.end_reason,
        rec.success,
        rec.steps,
        rec.llm_calls,
        rec.prompt_tokens,
        rec.cached_prompt_tokens,
        rec.completion_tokens,
        rec.cost_usd,
        rec.max_depth,
    ) == (f"{unit.unit_id}-1", "success", True, 6, 7, 700, 128, 70, 0.25, 2)
    assert (
        rec.benchmark,
        rec.split,
        rec.task,
        rec.step_cap,
        rec.optimal_steps,
        rec.worker_id,
        rec.wall_s,
        rec.started_at,
        rec.ended_at,
        rec.test_double,
    ) == ("blocksworld", "3", "3@1", 12, 6, "w7", 3.5, 100.0, 103.5, True)
    assert (rec.model, rec.provider_model, rec.method, rec.label) == (unit.model_label, unit.model, "react", unit.method_label)


def test_an_infrastructure_failure_is_named_by_its_kind_first(unit):
    res = EpisodeResult("llm_error", False, 2, 3, error="no answer within 60s", error_kind="timeout")
    rec = episode_record(unit, 1, _outcome(unit, res))
    assert (rec.end_reason, rec.error) == ("infra_error", "timeout: no answer within 60s")
    res = EpisodeResult("llm_error", False, 2, 3, error="the reply was not JSON", error_kind="bad_request")
    assert episode_record(unit, 1, _outcome(unit, res)).end_reason == "llm_error"


def test_a_given_up_attempt_gets_the_journal_spend_and_its_place(unit):
    spent = AttemptSpend(calls=4, prompt_tokens=400, cached_prompt_tokens=0, completion_tokens=40, cost_usd=0.125)
    asked = []
    rec = episode_record(
        unit,
        2,
        None,
        end_reason="env_error",
        error="gave up after 2 failed attempts; last: x",
        worker_id="w1",
        started=50.0,
        now=60.0,
        journal_spend=lambda eid: asked.append(eid) or spent,
    )
    assert asked == [f"{unit.unit_id}-2"]
    assert (rec.end_reason, rec.llm_calls, rec.prompt_tokens, rec.cost_usd, rec.wall_s, rec.worker_id) == (
        "env_error",
        4,
        400,
        0.125,
        10.0,
        "w1",
    )
    assert (rec.benchmark, rec.success, rec.steps) == ("blocksworld", False, 0)

    def broken(eid):
        raise OSError("journal unreadable")

    rec = episode_record(
        unit, 2, _outcome(unit, crash=Crash("agent", "boom")), end_reason="env_error", error="e", journal_spend=broken
    )
    assert (rec.llm_calls, rec.cost_usd, rec.split) == (0, 0.0, "3")  # the row matters more than its spend
    with pytest.raises(ValueError, match="no result and no end reason"):
        episode_record(unit, 1, None)


# -- the in-process pool ------------------------------------------------------------------------
class _Runner:
    def __init__(self, wid, gate):
        self.wid, self.gate = wid, gate

    def run_unit(self, work: UnitWork, attempt: int) -> EpisodeOutcome:
        self.gate.wait(10)
        if work.sampling_seed < 0:
            raise RuntimeError("runner broke")
        return EpisodeOutcome(
            unit_id=work.unit_id,
            attempt=attempt,
            episode_id=f"{work.unit_id}-{attempt}",
            worker_id=self.wid,
            pid=0,
            started_at=0.0,
            env=EnvFacts(work.benchmark),
            model=work.model,
            test_double=True,
            result=EpisodeResult("success", True, 1, 1),
        )


def test_the_in_process_pool_runs_attempts_on_its_own_workers(unit):
    import dataclasses

    gate = threading.Event()
    pool = InProcessWorkerPool(lambda wid: _Runner(wid, gate), session="ab")
    assert pool.start(2) == {"ab-t001": "local", "ab-t002": "local"}
    bad = dataclasses.replace(unit, sampling_seed=-1)
    s1 = pool.submit(Pending(unit, 1))
    s2 = pool.submit(Pending(bad, 3))
    assert {s1.worker_id, s2.worker_id} == {"ab-t001", "ab-t002"} and not pool.has_idle()
    assert pool.wait(0.05) == [] and pool.in_flight() == 2
    gate.set()
    deadline, keys = time.monotonic() + 10, []
    while len(keys) < 2 and time.monotonic() < deadline:
        keys += pool.wait(1.0)
        keys = list(dict.fromkeys(keys))
    fins = sorted((pool.collect(k) for k in keys), key=lambda f: f.pending.attempt)
    ok, broke = fins
    assert ok.failure is None and ok.outcome.episode_id == f"{unit.unit_id}-1" and ok.outcome.worker_id == s1.worker_id
    assert (broke.failure, broke.error, broke.outcome) == ("task_raised", "RuntimeError: runner broke", None)
    assert pool.in_flight() == 0 and pool.has_idle() and sorted(s.units for s in pool.slots) == [0, 1]
    assert pool.add_worker().worker_id == "ab-t003"
    pool.shutdown()


# -- the sink channel without a sink --------------------------------------------------------------
def test_rows_written_directly_put_events_first_and_terminal_rows_last(tmp_path, unit):
    buf = EventBuffer()
    buf.add("sink_lost", severity="error", reason="test")
    ch = SinkChannel(tmp_path, "run1", buf, session="s1")
    res = EpisodeResult("success", True, 6, 7)
    ch.send([episode_record(unit, 1, _outcome(unit, res))])
    eps, bad = read_table(tmp_path, "episodes")
    evs, _ = read_table(tmp_path, "events")
    assert bad == [] and eps.column("episode_id").to_pylist() == [f"{unit.unit_id}-1"]
    assert evs.column("kind").to_pylist() == ["sink_lost"] and not buf
    assert eps.column("run_id").to_pylist() == ["run1"]


# -- resolved settings ------------------------------------------------------------------------------
def test_every_resolved_config_round_trips_and_the_worker_builds_it_exactly():
    from recap.config import ABLATIONS, PROFILES, ConfigError, build_config
    from recap.methods import METHODS
    from workers.episode_worker import agent_from_config

    n = 0
    for method, (_, cfg_cls) in METHODS.items():
        for profile in (None, *PROFILES):
            for ablation in (None, *ABLATIONS):
                for bench in (None, "robotouille", "alfworld"):
                    try:
                        cfg = build_config(cfg_cls, profile, ablation, get_benchmark(bench) if bench else None)
                    except ConfigError:
                        continue  # an ablation that does not apply to the method
                    text = cfg.to_json()
                    assert cfg_cls.from_json(text) == cfg
                    assert agent_from_config(method, text).config == cfg
                    n += 1
    assert n > 100
    with pytest.raises(ConfigError, match=r"unknown: colour; missing: -"):
        agent_from_config("react", json.dumps({**json.loads(build_config(METHODS["react"][1]).to_json()), "colour": 1}))
    with pytest.raises(ConfigError, match=r"missing: window\b"):
        cfg = json.loads(build_config(METHODS["react"][1]).to_json())
        del cfg["window"]
        agent_from_config("react", json.dumps(cfg))


def test_a_unit_hands_its_worker_the_resolved_settings_not_the_raw_ones(tmp_path):
    text = SPEC.format(out=tmp_path / "r2").replace(
        "[{method: react}]", "[{method: recap, profile: paper, ablation: no_think, settings: {window: 32}}]"
    )
    u = expand(parse_spec(text, "sweep.yaml")).units[0]
    work = u.work()
    assert work.method_config == u.method_config and json.loads(work.method_config)["window"] == 32
    assert json.loads(work.method_config)["think"] == "none"
    assert not hasattr(work, "settings") and not hasattr(work, "profile")


# -- the two pools give the same run ----------------------------------------------------------------
def test_the_in_process_executor_writes_the_rows_the_ray_executor_writes(ray_address, tmp_path):
    """The session does not care where attempts run: the same sweep through Ray actors and
    through threads of the driver writes the same episodes, steps and messages."""
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.sqlview import open_tables
    from pipeline.store import RunStore

    body = """run: same
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}, {{method: recap}}]
environments: [{{benchmark: blocksworld, instances: [blocksworld/3@1, blocksworld/4@2]}}]
workers: 2
"""
    rows = {}
    for executor in ("ray", "in-process"):
        out = tmp_path / executor
        text = body.format(out=out)
        spec = parse_spec(text, "sweep.yaml")
        summary = Driver(prepare(spec, text), make_backend(spec), progress="off", executor=executor).run()
        assert summary.exit_code() == 0 and summary.finished_now == 4
        con, bad = open_tables(RunStore(out))
        assert bad == []
        rows[executor] = (
            con.execute(
                "select unit_id, attempt, end_reason, success, steps, llm_calls, prompt_tokens, "
                "completion_tokens, cost_usd, max_depth from episodes order by unit_id"
            ).fetchall(),
            con.execute("select episode_id, seq, role, content from messages order by episode_id, seq").fetchall(),
            con.execute(
                "select episode_id, index, env_step, action, valid, observation from steps order by episode_id, index"
            ).fetchall(),
            sorted({w[:4] + w[5] for (w,) in con.execute("select distinct worker_id from episodes").fetchall()}),
        )
    ray_rows, local_rows = rows["ray"], rows["in-process"]
    assert ray_rows[:3] == local_rows[:3] and len(ray_rows[1]) > 40
    assert ray_rows[3][0][-1] == "w" and local_rows[3][0][-1] == "t"  # actors vs threads
