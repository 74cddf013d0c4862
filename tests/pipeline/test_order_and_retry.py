"""The order units start in (``order: interleaved | plan``) and ``--retry errors``.

Interleaved (the default): arms (method x model) take turns and, within an arm, instances come
in a seeded shuffle spread over benchmarks and splits, so a cap that binds early leaves a
balanced subsample. ``--retry errors`` (``retry="errors"``) re-runs units whose latest
completing row ended env_error / llm_error, under the next attempt number. Unit-level tests
first (no Ray), then a capped run and an env_error retried end to end on a local Ray.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.driver import Driver, prepare
from pipeline.errors import PipelineError, SpecError
from pipeline.gateway_backend import make_backend
from pipeline.resume import RunState, UnitQueue, infra_failure, load_state
from pipeline.spec import parse_spec, with_overrides
from pipeline.sqlview import open_tables
from pipeline.store import RunStore
from pipeline.summary import collect
from pipeline.units import expand, order_seed, order_units, stratum
from schemas.parts import PartWriter
from schemas.records import EpisodeRecord, EventRecord

MIXED = """run: mixed
output: /tmp/never-written
models:
  - model: offline/expert
  - model: offline/random
methods:
  - method: recap
  - method: react
  - method: cot
environments:
  - benchmark: blocksworld
    tasks: ["3", "4"]
    limit: 2
  - benchmark: robotouille
    tasks: [synchronous, asynchronous]
    limit: 2
seeds: [0, 1]
"""


def _arm(u) -> tuple[str, str]:
    return (u.method_label, u.model_label)


def _mixed(text: str = MIXED):
    spec = parse_spec(text, "sweep.yaml")
    return spec, expand(spec)


# --------------------------------------------------------------------------------------------
# the order (no Ray)
# --------------------------------------------------------------------------------------------
def test_interleaved_order_balances_every_prefix_per_arm():
    spec, plan = _mixed()
    assert spec.order == "interleaved"
    order = order_units(plan.units, spec)
    arms = {_arm(u) for u in plan.units}
    assert len(arms) == 6 and len(plan.units) == 8 * 3 * 2 * 2
    # a permutation of the plan: same units, same ids
    assert sorted(u.unit_id for u in order) == sorted(u.unit_id for u in plan.units)
    counts = Counter({a: 0 for a in arms})
    for k, u in enumerate(order, 1):
        counts[_arm(u)] += 1
        assert max(counts.values()) - min(counts.values()) <= 1, f"prefix {k}: {counts}"


def test_interleaved_order_spreads_instances_over_benchmarks_and_splits_and_pairs_arms():
    spec, plan = _mixed()
    order = order_units(plan.units, spec)
    strata = {stratum(u.instance_id) for u in plan.units}
    assert strata == {"blocksworld/3", "blocksworld/4", "robotouille/synchronous", "robotouille/asynchronous"}
    per_arm: dict[tuple[str, str], list] = {}
    for u in order:
        per_arm.setdefault(_arm(u), []).append(u)
    for arm, units in per_arm.items():
        # the first 4 units of an arm cover every stratum; its first 8 every instance, with seed 0
        assert {stratum(u.instance_id) for u in units[:4]} == strata, arm
        assert {u.instance_id for u in units[:8]} == {u.instance_id for u in plan.units} and {
            u.sampling_seed for u in units[:8]
        } == {0}
    # every arm gets the same (instance, seed) pairs in the same order: a capped run's units pair up
    sequences = {tuple((u.instance_id, u.sampling_seed) for u in units) for units in per_arm.values()}
    assert len(sequences) == 1
    # the first round gives each arm one unit, all on the same instance
    assert len({_arm(u) for u in order[:6]}) == 6 and len({u.instance_id for u in order[:6]}) == 1
    # the plan order covers one instance of one benchmark in the same prefix
    assert len({u.instance_id for u in plan.units[:12]}) == 1
    assert len({u.instance_id for u in order[:24]}) == 4
    assert {stratum(u.instance_id) for u in order[:24]} == strata


def test_order_is_deterministic_and_seeded_by_the_run_name():
    spec1, plan1 = _mixed()
    spec2, plan2 = _mixed()
    first = [u.unit_id for u in order_units(plan1.units, spec1)]
    assert first == [u.unit_id for u in order_units(plan2.units, spec2)]
    assert order_seed(spec1) == order_seed(spec2)
    # the output folder and the caps do not change it
    moved = with_overrides(spec1, output="/tmp/elsewhere", run_cap_usd=3.0, workers=9)
    assert [u.unit_id for u in order_units(expand(moved).units, moved)] == first
    # another run name: another shuffle, the same units and ids
    spec3, plan3 = _mixed(MIXED.replace("run: mixed", "run: other"))
    other = [u.unit_id for u in order_units(plan3.units, spec3)]
    assert other != first and sorted(other) == sorted(first)


def test_plan_order_keeps_the_old_order_and_unit_ids_do_not_depend_on_the_order():
    spec, plan = _mixed()
    pspec, pplan = _mixed(MIXED + "order: plan\n")
    assert pspec.order == "plan"
    assert [u.unit_id for u in order_units(pplan.units, pspec)] == [u.unit_id for u in pplan.units]
    # instances, then methods, models, seeds
    first = pplan.units[:12]
    assert len({u.instance_id for u in first}) == 1
    assert [(u.method_label, u.model_label, u.sampling_seed) for u in first[:4]] == [
        ("recap", "offline/expert", 0),
        ("recap", "offline/expert", 1),
        ("recap", "offline/random", 0),
        ("recap", "offline/random", 1),
    ]
    # the order is not part of any hash: the same ids and keys, and plan.json lists the plan order either way
    assert [(u.key, u.unit_id) for u in pplan.units] == [(u.key, u.unit_id) for u in plan.units]
    assert pplan.to_json() == plan.to_json()
    with pytest.raises(SpecError) as err:
        parse_spec(MIXED + "order: random\n", "sweep.yaml")
    assert str(err.value).startswith("sweep.yaml: order: Input should be 'interleaved' or 'plan'")


def test_resume_continues_in_the_same_order():
    spec, plan = _mixed()
    order = order_units(plan.units, spec)
    done = {u.unit_id for u in order[:7]} | {order[20].unit_id}
    q = UnitQueue(order_units(expand(spec).units, spec), RunState(completed=done))
    taken = []
    while (p := q.take()) is not None:
        taken.append(p.unit.unit_id)
    assert taken == [u.unit_id for u in order if u.unit_id not in done]


# --------------------------------------------------------------------------------------------
# --retry errors: the selection (no Ray)
# --------------------------------------------------------------------------------------------
SMALL = """run: retry
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments: [{{benchmark: blocksworld, tasks: ["3", "4", "5"]}}]
"""


def _ep(uid: str, attempt: int, reason: str, error: str | None = None, method: str = "react") -> EpisodeRecord:
    return EpisodeRecord(
        f"{uid}-{attempt}",
        uid,
        attempt,
        "blocksworld",
        "",
        "",
        "x",
        0,
        method,
        "{}",
        "offline/expert",
        reason,
        reason == "success",
        0,
        0,
        0,
        0,
        0,
        0.0,
        0.0,
        0,
        4.0,
        error=error,
        test_double=True,
        label=method,
    )


def _folder(tmp_path: Path, text: str = SMALL):
    out = tmp_path / "run"
    text = text.format(out=out)
    spec = parse_spec(text)
    plan = expand(spec)
    store = RunStore(out)
    store.create_identity(spec.run)
    store.write_text("spec.yaml", text)
    store.write_text("plan.json", plan.to_json())
    return out, plan, store


def test_retry_errors_selects_env_and_llm_errors_under_the_next_attempt(tmp_path, capsys):
    out, plan, store = _folder(tmp_path)
    a, b, c, d, e, f, g, h, i = (u.unit_id for u in plan.units[:9])
    gave_up = "gave up after 3 failed attempts; last: agent: KeyError: 'x'"
    PartWriter(out, "t").write_records(
        "r",
        [
            _ep(a, 1, "success"),
            _ep(b, 1, "env_error", "ExplicitDataDirError: data folder '/nope' does not exist"),
            _ep(c, 1, "llm_error", "bad_request: BadRequestError: temperature must be <= 2"),
            _ep(d, 1, "llm_error", "server_error: APIConnectionError: Connection refused"),  # infrastructure
            _ep(e, 1, "env_error", "FileNotFoundError: x"),
            _ep(e, 2, "success"),  # fixed already
            _ep(f, 3, "env_error", gave_up),  # an agent crash given up on
            *[EventRecord(1.0, "driver", "attempt_failed", unit_id=f, detail=json.dumps({"attempt": n})) for n in (1, 2, 3)],
            _ep(g, 1, "budget_exhausted", "run budget spent"),
            _ep(h, 1, "step_cap"),  # a real outcome
            # i: never started
        ],
    )
    assert infra_failure("env_error", gave_up) is None

    plain = load_state(store)
    assert plain.completed == {a, b, c, e, f, h}
    assert plain.errored == {b: "env_error", c: "llm_error", f: "env_error"}
    assert plain.infra_failed == {d: "server_error"}
    q = UnitQueue(plan.units, plain)
    assert sorted((p.unit.unit_id, p.attempt) for p in iter(q.take, None)) == sorted([(d, 2), (g, 2), (i, 1)])

    errors = load_state(store, retry="errors")
    assert errors.completed == {a, e, h}
    assert errors.errored == plain.errored and errors.infra_failed == {d: "server_error"}
    assert errors.failures == {}  # the give-up row spent f's failed attempts: a fresh count
    q = UnitQueue(plan.units, errors)
    assert sorted((p.unit.unit_id, p.attempt) for p in iter(q.take, None)) == sorted(
        [(b, 2), (c, 2), (d, 2), (f, 4), (g, 2), (i, 1)]
    )

    with pytest.raises(ValueError):
        load_state(store, retry="everything")  # type: ignore[arg-type]
    with pytest.raises(PipelineError, match="--retry must be one of infra, errors"):
        Driver(None, None, retry="all")  # type: ignore[arg-type]

    # status counts them as done and says how to run them again
    report = collect(store)
    assert (report.completed, report.errored, report.failed, report.budget_stopped) == (6, 3, 1, 1)
    assert main(["status", str(out)]) == 0
    text = capsys.readouterr().out
    assert (
        f"3 done units ended in env_error or llm_error; once the cause is fixed, run them again with: recap resume {out} --retry errors"
        in text
    )

    # the retry ran: b fixed, c failed again (done again, retried again on request), an infra failure after an error
    PartWriter(out, "t2").write_records(
        "r2",
        [
            _ep(b, 2, "success"),
            _ep(c, 2, "llm_error", "bad_request: still bad"),
            _ep(f, 4, "llm_error", "timeout: no answer within 120s"),
        ],
    )
    again = load_state(store, retry="errors")
    assert b in again.completed and c not in again.completed and f not in again.completed
    assert again.infra_failed == {d: "server_error", f: "timeout"}
    plain = load_state(store)
    assert {b, c, f} <= plain.completed and plain.infra_failed == {d: "server_error"}  # f's env_error row still completes it


def test_status_shows_planned_and_done_per_arm(tmp_path, capsys):
    out, plan, store = _folder(
        tmp_path, SMALL.replace("methods: [{{method: react}}]", "methods: [{{method: react}}, {{method: cot}}]")
    )
    react = [u.unit_id for u in plan.units if u.method_label == "react"]
    cot = [u.unit_id for u in plan.units if u.method_label == "cot"]
    assert len(react) == len(cot) == 9
    PartWriter(out, "t").write_records(
        "r",
        [
            _ep(react[0], 1, "success"),
            _ep(react[1], 1, "step_cap"),
            _ep(react[2], 1, "budget_exhausted", "run budget spent"),
            _ep(cot[0], 1, "success", method="cot"),
            _ep(cot[1], 1, "llm_error", "auth: AuthenticationError: bad key", method="cot"),
        ],
    )
    groups = {g.method: g for g in collect(store).groups}
    assert [
        (g.planned, g.done, g.success, g.budget_stopped, g.failed, g.not_started) for g in (groups["react"], groups["cot"])
    ] == [(9, 2, 1, 1, 0, 6), (9, 1, 1, 0, 1, 7)]
    assert main(["status", str(out)]) == 0
    lines = capsys.readouterr().out.splitlines()
    header = next(line for line in lines if "┃" in line and "planned" in line)
    assert [
        w for w in ("arm", "model", "planned", "done", "success", "capped", "gave up", "not started") if w not in header
    ] == []
    row = next(line for line in lines if line.strip("│ ").startswith("react"))
    cells = [c.strip() for c in row.strip().strip("│").split("│")]
    assert cells[:8] == ["react", "offline/expert (test double)", "9", "2", "1/2 (50%)", "1", "0", "6"]
    row = next(line for line in lines if line.strip("│ ").startswith("cot"))
    assert [c.strip() for c in row.strip().strip("│").split("│")][:8] == [
        "cot",
        "offline/expert (test double)",
        "9",
        "1",
        "1/1 (100%)",
        "0",
        "1",
        "7",
    ]


def test_report_coverage_table_reads_the_plan(tmp_path):
    from reports.build import build_report
    from reports.views import named_query, open_runs

    out, plan, store = _folder(
        tmp_path, SMALL.replace("methods: [{{method: react}}]", "methods: [{{method: react}}, {{method: cot}}]")
    )
    react = [u.unit_id for u in plan.units if u.method_label == "react"]
    cot = [u.unit_id for u in plan.units if u.method_label == "cot"]
    run_id = store.require_identity().run_id
    PartWriter(out, "t").write_records(
        run_id,
        [
            _ep(react[0], 1, "success"),
            _ep(react[1], 1, "env_error", "x"),
            _ep(react[2], 1, "budget_exhausted", "run budget spent"),
            _ep(cot[0], 1, "llm_error", "auth: AuthenticationError: bad key", method="cot"),
            _ep(
                cot[1],
                1,
                "env_error",
                "gave up after 3 failed attempts (infrastructure: worker_lost); last: ActorDiedError: x",
                method="cot",
            ),
            _ep(cot[2], 1, "budget_exhausted", "run budget spent", method="cot"),
            _ep(cot[2], 2, "success", method="cot"),
        ],
    )
    report = build_report([out])
    table = next(t for s in report.sections for t in s.tables if t.name == "coverage")
    got = [
        {
            k: r[k]
            for k in (
                "run_id",
                "model_label",
                "arm",
                "planned",
                "finished",
                "successes",
                "capped",
                "gave_up",
                "not_started",
                "planned_from",
            )
        }
        for r in table.rows
    ]
    assert got == [
        {
            "run_id": run_id,
            "model_label": "offline/expert (test double)",
            "arm": "cot",
            "planned": 9,
            "finished": 1,
            "successes": 1,
            "capped": 0,
            "gave_up": 2,
            "not_started": 6,
            "planned_from": "plan.json",
        },
        {
            "run_id": run_id,
            "model_label": "offline/expert (test double)",
            "arm": "react",
            "planned": 9,
            "finished": 2,
            "successes": 1,
            "capped": 1,
            "gave_up": 0,
            "not_started": 6,
            "planned_from": "plan.json",
        },
    ]
    assert "No readable plan.json" not in table.note
    # without a plan (a plain `recap sql` session): planned falls back to the units with rows, and says so
    con = open_runs([out])
    rows = named_query(con, "coverage").dicts()
    assert [(r["arm"], r["planned"], r["not_started"], r["planned_from"]) for r in rows] == [
        ("cot", 3, 0, "episode rows"),
        ("react", 3, 0, "episode rows"),
    ]
    # the SQL rule for infrastructure failures is the pipeline's
    samples = [
        ("llm_error", "server_error: x"),
        ("llm_error", "auth: y"),
        ("llm_error", "bad_request: NotFoundError: 404"),
        ("llm_error", "bad_request: temperature"),
        ("llm_error", "context length exceeded"),
        ("llm_error", None),
        ("env_error", "gave up after 3 failed attempts (infrastructure: client); last: client: boom"),
        ("env_error", "gave up after 3 failed attempts; last: ActorDiedError: gone"),
        ("env_error", "gave up after 3 failed attempts; last: client: ClientError"),
        ("env_error", "gave up after 3 failed attempts; last: agent: KeyError"),
        ("env_error", "FileNotFoundError"),
        ("success", None),
        ("budget_exhausted", "run budget spent"),
        ("llm_error", "rate_limit: slow down"),
        # schema version 2 writes infrastructure failures as infra_error
        ("infra_error", "auth: y"),
        ("infra_error", "bad_request: NotFoundError: 404"),
        ("infra_error", "odd"),
        ("infra_error", "gave up after 1 failed attempts (infrastructure: worker_lost); last: ActorDiedError: x"),
        ("infra_error", None),
    ]
    got = con.execute(
        "SELECT infra_failure_kind(r, e) FROM (SELECT unnest($1) AS r, unnest($2) AS e)",
        [[s[0] for s in samples], [s[1] for s in samples]],
    ).fetchall()
    assert [g[0] for g in got] == [infra_failure(r, e) for r, e in samples]
    con.close()


# --------------------------------------------------------------------------------------------
# end to end on a local Ray
# --------------------------------------------------------------------------------------------


CAPPED = """models:
  - model: offline/expert
  - model: offline/random
methods:
  - method: react
  - method: cot
environments:
  - benchmark: blocksworld
    tasks: ["3", "4"]
limits: {{llm_calls: 4}}
workers: 2
run_cap_usd: {cap}
"""


def test_a_capped_run_samples_every_arm(ray_address, tmp_path, capsys):
    out = tmp_path / "capped"
    text = f"run: {out.name}\noutput: {out}\n" + CAPPED.format(cap=0.04)
    spec = parse_spec(text, "sweep.yaml")
    prepared = prepare(spec, text)
    assert len(prepared.plan.units) == 24
    summary = Driver(prepared, make_backend(spec), progress="off").run()
    assert summary.exit_code() == 3 and summary.stopped is not None
    con, _ = open_tables(RunStore(out))
    rows = con.execute("select unit_id, method, model, instance_id, end_reason, cost_usd from episodes").fetchall()
    assert 4 <= len(rows) < 24
    started = {r[0] for r in rows}
    # what started is a prefix of the interleaved order: balanced over the 4 arms, spread over both sizes
    order = [u.unit_id for u in order_units(prepared.plan.units, spec)]
    assert started == set(order[: len(started)])
    per_arm = Counter((r[1], r[2]) for r in rows)
    assert len(per_arm) == 4 and max(per_arm.values()) - min(per_arm.values()) <= 1, per_arm
    # round 0 gives each arm the same first instance, round 1 one of the other size
    assert {r[3].split("@")[0] for r in rows} == {"blocksworld/3", "blocksworld/4"}, rows
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert "planned" in status and "not started" in status
    groups = collect(RunStore(out)).groups
    assert len(groups) == 4 and all(g.planned == 6 for g in groups)
    assert all(g.planned - g.not_started >= 1 for g in groups)  # every arm sampled


def test_an_env_error_unit_is_retried_at_attempt_2_with_retry_errors(ray_address, tmp_path):
    out = tmp_path / "enverr"
    body = """models: [{model: offline/expert}]
methods: [{method: react}]
environments:
  - benchmark: blocksworld
    instances: [blocksworld/3@1]
  - benchmark: robotouille
    tasks: [synchronous/0_cheese_sandwich]
    limit: 1
workers: 2
"""
    broken = f"run: {out.name}\noutput: {out}\n" + body.replace(
        "    limit: 1\n", "    limit: 1\n    options: {data_dir: " + str(tmp_path / "no-such-data") + "}\n"
    )
    spec = parse_spec(broken, "sweep.yaml")
    first = Driver(prepare(spec, broken, check_keys=False), make_backend(spec), progress="off").run()
    assert (first.finished_now, first.infra_failed, first.exit_code()) == (2, 0, 0)
    con, _ = open_tables(RunStore(out))
    assert sorted(con.execute("select instance_id, attempt, end_reason from episodes").fetchall()) == [
        ("blocksworld/3@1", 1, "success"),
        ("robotouille/synchronous/0_cheese_sandwich@42", 1, "env_error"),
    ]

    # the data folder fixed (env options are not part of the unit hash); a plain resume re-runs nothing
    fixed = f"run: {out.name}\noutput: {out}\n" + body
    (out / "spec.yaml").write_text(fixed)
    spec = parse_spec(fixed, "sweep.yaml")
    plain = Driver(prepare(spec, fixed, check_keys=False), make_backend(spec), progress="off").run()
    assert (plain.completed_before, plain.finished_now, plain.exit_code()) == (2, 0, 0)
    retried = Driver(prepare(spec, fixed, check_keys=False), make_backend(spec), progress="off", retry="errors").run()
    assert (retried.completed_before, retried.finished_now, retried.retried_errors, retried.exit_code()) == (1, 1, 1, 0)
    con, _ = open_tables(RunStore(out))
    assert sorted(con.execute("select instance_id, attempt, end_reason from episodes").fetchall()) == [
        ("blocksworld/3@1", 1, "success"),
        ("robotouille/synchronous/0_cheese_sandwich@42", 1, "env_error"),
        ("robotouille/synchronous/0_cheese_sandwich@42", 2, "success"),
    ]  # the earlier row kept for the record
    detail = json.loads(
        con.execute("select detail from events where kind = 'run_resumed' order by ts desc limit 1").fetchone()[0]
    )
    assert detail["retrying_errors"] == 1 and detail["order"] == "interleaved"
    assert load_state(RunStore(out), retry="errors").errored == {}


def test_a_unit_given_up_after_worker_deaths_exits_4_and_the_summary_says_so(ray_address, tmp_path, capsys):
    import os
    import signal
    import threading
    import time

    import ray

    from pipeline.driver import EXIT_INFRA, Hooks
    from tests.pipeline.helpers import TinyBackend

    out = tmp_path / "deaths"
    text = (
        f"run: {out.name}\noutput: {out}\n"
        + """models: [{model: offline/tiny}]
methods: [{method: react}]
environments: [{benchmark: blocksworld, instances: [blocksworld/3@1, blocksworld/3@2]}]
workers: 2
max_attempts: 2
"""
    )
    spec = parse_spec(text, "sweep.yaml")
    prepared = prepare(spec, text, check_keys=False)
    target = next(u.unit_id for u in prepared.plan.units if u.instance_id == "blocksworld/3@1")

    backend = TinyBackend(latency_s=0.15)

    def kill_target(unit, attempt, actor):
        if unit.unit_id != target:
            return
        # every model call waits until the kill: the episode cannot finish first on a loaded machine
        ray.get(backend.budget.hold.remote())

        def kill():
            try:
                time.sleep(0.3)  # into the episode (its reset, maybe a call)
                os.kill(ray.get(actor.pid.remote()), signal.SIGKILL)
            finally:
                ray.get(backend.budget.release.remote())

        threading.Thread(target=kill, daemon=True).start()

    summary = Driver(prepared, backend, progress="off", hooks=Hooks(on_dispatch=kill_target)).run()
    assert (summary.abandoned, summary.infra_failed, summary.infra_kinds, summary.finished_now) == (1, 1, {"worker_lost": 1}, 1)
    assert summary.exit_code() == EXIT_INFRA == 4
    assert "1 unit ended in an infrastructure failure (worker_lost 1)" in summary.retry_hint()
    assert load_state(RunStore(out)).infra_failed == {target: "worker_lost"}
    report = collect(RunStore(out))
    assert (report.completed, report.failed, report.failed_kinds) == (1, 1, {"worker_lost": 1})
    capsys.readouterr()
    assert main(["status", str(out)]) == 0
    status = capsys.readouterr().out
    assert "1 failed on infrastructure" in status
    assert (
        f"1 unit ended in an infrastructure failure (worker_lost 1); fix the cause, then retry them with: recap resume {out}"
        in status
    )


def test_a_give_up_whose_last_error_names_a_dead_actor_counts_as_infrastructure(tmp_path):
    """The worker lived but its task failed on a dead actor (attempt_failed, no marker): the row
    reads as worker_lost to resume and status, so the session counts it as failed (exit 4)."""
    from pipeline.driver import RunSummary
    from pipeline.resume import Pending
    from pipeline.worker_pool import Finished, Slot

    out = tmp_path / "one"
    text = (
        f"run: one\noutput: {out}\n"
        + """models: [{model: offline/tiny}]
methods: [{method: react}]
environments: [{benchmark: blocksworld, instances: [blocksworld/3@1]}]
max_attempts: 1
"""
    )
    spec = parse_spec(text, "sweep.yaml")
    d = Driver(prepare(spec, text, check_keys=False), None, progress="off")
    unit = d.p.plan.units[0]
    d.summary = RunSummary(location=str(out), run="one", run_id="x", total=1, completed_before=0)
    d.failures, d.queue = {}, UnitQueue([], RunState())
    d._failed_attempt(
        Finished(Slot("w1", None), Pending(unit, 1), 0.0),
        "attempt_failed",
        "ActorDiedError: The actor died unexpectedly before finishing this task.",
    )
    (rec,) = d.records_out
    assert rec.error.startswith("gave up after 1 failed attempts; last: ActorDiedError")
    assert infra_failure(rec.end_reason, rec.error) == "worker_lost"
    assert (d.summary.infra_failed, d.summary.infra_kinds, d.summary.finished_now) == (1, {"worker_lost": 1}, 0)
    assert d.summary.exit_code() == 4
