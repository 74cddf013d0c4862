"""Guards that must hold against a hostile user or provider: read-only SQL, caps, the driver lock.

* sql: every attack of ``tests/reports/test_sql_read_only.py`` (statements that would write,
  unlock the connection, or read outside the views) sent through the real ``recap sql`` entry
  against a finished run folder of the real pipeline: each exits 2 with one line on stderr and
  nothing on stdout, and every file of the run folder (hidden ones too) keeps its bytes.
* sqlres: every memory and time attack of the same test file (1e8-value lists, 1 GB strings,
  recursive CTEs, huge sorts and results, endless cross joins) through ``recap sql`` as a process
  with ``--timeout 2`` and ``--memory-limit 256MB`` (512MB for the time attacks, whose constant
  memory is close to 256MB's stop threshold on a loaded machine): each stopped with one line naming
  the limit, the peak RSS of the command's process tree under its memory limit, the run folder unchanged.
* caps: a gateway with a small run cap against the loopback fake OpenAI server in each hostile
  mode (usage reported negative, zero, huge, fractional, missing, negative cached; n choices
  slipping past the config; a negative / NaN / infinite cost figure), called until the budget
  refuses: the ledger never passes the cap, and never bills less than the provider really
  generated (the fake server's own token counts at the model's price).
* unreadable: a provider that answers only HTTP 200s nobody can use (not JSON, cut short, HTML,
  no choices, no message, null content - each mode alone, then all at random) against a small
  run cap, over three gateway sessions on one run folder (a run and two resumes): the provider's
  own bill never passes the cap, and the later sessions send nothing.
* lock: synchronised contenders for one run folder's driver lock (threads, then processes),
  each trial on a fresh folder (half the thread trials over a stale lock file): exactly one
  winner each, the others refused with one line.

The helpers are the unit tests' own (imported, not copied): the attack list and its
placeholders, the hostile-provider gateway config and loop, the lock race.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import itertools
import json
import multiprocessing as mp
import os
import queue
import socket
import warnings
from collections import Counter
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import Lab, ScenarioResult, blocks, run_driver, sweep


# --------------------------------------------------------------------------------------------
# sql
# --------------------------------------------------------------------------------------------
def _hashes(root: Path) -> dict[str, tuple[str, int]]:
    """Every file and folder under ``root`` (hidden ones too): (sha256, size)."""
    out: dict[str, tuple[str, int]] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[str(Path(dirpath, d).relative_to(root)) + "/"] = ("dir", 0)
        for f in filenames:
            p = Path(dirpath, f)
            data = p.read_bytes()
            out[str(p.relative_to(root))] = (hashlib.sha256(data).hexdigest(), len(data))
    return out


def _bytes_changed(before: dict[str, tuple[str, int]], after: dict[str, tuple[str, int]]) -> tuple[int, list[str]]:
    """(bytes of the files that changed, appeared or vanished, their names)."""
    changed = sorted(p for p in before.keys() | after.keys() if before.get(p) != after.get(p))
    # a changed file counts its whole size (at least 1: a new empty file or folder is a change too)
    return sum(max(before.get(p, ("", 0))[1], after.get(p, ("", 0))[1], 1) for p in changed), changed


def _recap(argv: list[str]) -> tuple[int, str, str]:
    """``recap ARGV`` through the real CLI entry, in-process: (exit status, stdout, stderr)."""
    from pipeline.cli import main as recap_main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            rc = recap_main(argv)
        except SystemExit as exc:  # argparse
            rc = exc.code if isinstance(exc.code, int) else 1
    return rc, out.getvalue(), err.getvalue()


def sql_attacks(lab: Lab, units: int = 4) -> ScenarioResult:
    """Every write / escape attack through ``recap sql`` on a finished run: exit 2, 0 bytes changed."""
    from tests.reports.test_sql_read_only import ATTACKS, _fill

    res = ScenarioResult("SQL write attempts")
    lab.ray_address()
    out = lab.folder("sql-guard") / "run"
    summary, _ = run_driver(sweep(out, "  - model: offline/expert\n", blocks(units), run="sql-guard", workers=2))
    # setup checks (not runs): without a finished, readable run there is nothing to attack
    if not res.check("the run folder was built by a finished run (exit 0)", summary.exit_code() == 0, summary.exit_code()):
        return res
    rc, stdout, stderr = _recap(["sql", str(out), "SELECT count(*) AS n FROM episodes", "--json"])
    if not res.check(
        "a query still reads the run (exit 0)",
        rc == 0 and str(units) in stdout,
        f"exit {rc}: {stdout.strip()[:80]} {stderr.strip()[:200]}",
    ):
        return res
    first = _hashes(out)
    refused, total_bytes = 0, 0
    old_cwd = os.getcwd()
    os.chdir(out)  # relative paths in attacks ('evil.csv', EXPORT 'dump') land in the run folder
    try:
        for name, sql in ATTACKS.items():
            res.begin_run()
            before = _hashes(out)
            try:
                rc, stdout, stderr = _recap(["sql", str(out), _fill(sql, out)])
            except Exception as exc:  # a crash is not a refusal
                rc, stdout, stderr = None, "", f"{type(exc).__name__}: {exc}"
            n, changed = _bytes_changed(before, _hashes(out))
            total_bytes += n
            res.check(f"{name}: exit 2", rc == 2, f"exit {rc}: {stderr.strip()[:200]}")
            res.check(
                f"{name}: one error line on stderr, nothing on stdout",
                stdout == "" and len(stderr.splitlines()) == 1 and stderr.startswith("recap: error: sql: "),
                f"stdout {stdout[:80]!r}, stderr {stderr[:200]!r}",
            )
            res.check(f"{name}: 0 bytes changed", not changed, f"{n} bytes in {changed[:3]}")
            refused += int(rc == 2)
            res.end_run()
    finally:
        os.chdir(old_cwd)
    n_all, changed_all = _bytes_changed(first, _hashes(out))
    res.check("the run folder is byte-identical after every attack", not changed_all, changed_all[:5])
    total_bytes = max(total_bytes, n_all)
    res.name = f"SQL write attempts ({len(ATTACKS)} tried, {total_bytes} bytes changed)"
    res.notes.append(
        f"{len(ATTACKS)} attacks, {refused} refused, {total_bytes} bytes changed ({len(first)} files and folders hashed)"
    )
    return res


def sql_resource_attacks(lab: Lab, units: int = 4) -> ScenarioResult:
    """Every memory and time attack of ``tests/reports/test_sql_read_only.py`` through ``recap sql`` (a
    process of its own, peak RSS of its process tree measured) on a finished run: exit 2, one line naming
    the limit hit, peak RSS under the memory limit, 0 bytes changed."""
    from tests.reports.test_sql_read_only import (
        ATTACK_MEMORY,
        ATTACK_MEMORY_BYTES,
        ATTACK_TIMEOUT_S,
        MEMORY_ATTACKS,
        TIME_ATTACK_MEMORY,
        TIME_ATTACK_MEMORY_BYTES,
        TIME_ATTACKS,
        recap_measured,
    )

    res = ScenarioResult("SQL resource attacks")
    lab.ray_address()
    out = lab.folder("sql-resources") / "run"
    summary, _ = run_driver(sweep(out, "  - model: offline/expert\n", blocks(units), run="sql-resources", workers=2))
    if not res.check("the run folder was built by a finished run (exit 0)", summary.exit_code() == 0, summary.exit_code()):
        return res
    first = _hashes(out)
    attacks = [(n, q, "memory") for n, q in MEMORY_ATTACKS.items()] + [(n, q, "time") for n, q in TIME_ATTACKS.items()]
    peak_all, stopped = 0, {"memory": 0, "time": 0}
    for name, sql, limit in attacks:
        res.begin_run()
        memory, memory_bytes = (
            (ATTACK_MEMORY, ATTACK_MEMORY_BYTES) if limit == "memory" else (TIME_ATTACK_MEMORY, TIME_ATTACK_MEMORY_BYTES)
        )
        argv = ["sql", str(out), sql, "--memory-limit", memory, "--timeout", str(ATTACK_TIMEOUT_S)]
        try:
            rc, stdout, stderr, peak = recap_measured(argv)
        except Exception as exc:  # a crash is not a stop
            rc, stdout, stderr, peak = None, "", f"{type(exc).__name__}: {exc}", 0
        peak_all = max(peak_all, peak)
        want = f"recap: error: sql: {limit} limit {ATTACK_MEMORY if limit == 'memory' else f'{ATTACK_TIMEOUT_S}s'} hit"
        res.check(f"{name}: exit 2", rc == 2, f"exit {rc}: {stderr.strip()[:200]}")
        res.check(
            f"{name}: one line naming the {limit} limit, nothing on stdout",
            stdout == "" and len(stderr.splitlines()) == 1 and stderr.startswith(want),
            f"stdout {stdout[:80]!r}, stderr {stderr[:200]!r}",
        )
        res.check(f"{name}: peak RSS under {memory}", peak < memory_bytes, f"{peak / 1e6:.0f}MB")
        stopped[limit] += int(rc == 2 and stderr.startswith(want))
        res.end_run()
    changed = _bytes_changed(first, _hashes(out))[1]
    res.check("the run folder is byte-identical after every attack", not changed, changed[:5])
    rc, stdout, stderr = _recap(["sql", str(out), "SELECT count(*) AS n FROM episodes", "--json"])
    res.check("a query still reads the run (exit 0)", rc == 0 and str(units) in stdout, f"exit {rc}: {stderr[:200]}")
    res.name = f"SQL resource attacks ({len(attacks)} tried, peak RSS {peak_all / 1e6:.0f}MB)"
    res.notes.append(
        f"{len(attacks)} attacks: {stopped['memory']}/{len(MEMORY_ATTACKS)} stopped at the memory limit, "
        f"{stopped['time']}/{len(TIME_ATTACKS)} at the {ATTACK_TIMEOUT_S}s time limit; peak RSS {peak_all / 1e6:.0f}MB "
        f"(memory limit {ATTACK_MEMORY}, {TIME_ATTACK_MEMORY} for the time attacks)"
    )
    return res


# --------------------------------------------------------------------------------------------
# caps
# --------------------------------------------------------------------------------------------
#: usage-block lies of the fake server (``FAKE:<mode>`` in the prompt)
USAGE_LIES = ("negusage", "zerousage", "hugeusage", "nousage", "negcached", "fracusage")


def _run_dir(lab: Lab, name: str) -> Path:
    d = lab.folder(f"caps/{name}")
    (d / "run.json").write_text(json.dumps({"run_id": f"caps-{name}"}))
    return d


def cap_attacks(lab: Lab, cap_usd: float = 0.001) -> ScenarioResult:
    """A hostile provider against a small run cap: overspend and under-billing both $0."""
    import workers.gateway.core as core
    from recap.llm import LLMError
    from tests.workers.gateway.test_hostile_provider import config, events, spend_until_refused, true_bill_pico
    from workers.gateway.core import DeploymentGateway
    from workers.llm.accounting import USAGE_REJECTED_EVENT
    from workers.llm.litellm_setup import get_litellm
    from workers.llm.pricing import pico_to_usd, usd_to_pico

    get_litellm()
    res = ScenarioResult("cap attacks")
    cap_pico = usd_to_pico(cap_usd)
    attacks: list[tuple[str, dict[str, Any]]] = [(m, {"mode": m}) for m in USAGE_LIES]
    attacks += [("n=8 choices past the config", {"n": 8}), ("negative/NaN/inf cost figure", {"cost": True})]
    worst_over, worst_under = 0, 0
    per_attack: list[str] = []
    for name, attack in attacks:
        res.begin_run()
        server = lab.server(keep_bodies="n" in attack)
        run_dir = _run_dir(lab, name.split()[0].replace("/", "-"))
        cfg = config(server)
        if "n" in attack:  # model_copy does not validate: the gateway itself must size n choices
            cfg = cfg.model_copy(update={"params": {"max_tokens": 20, "n": attack["n"]}})
        suffix = f" FAKE:{attack['mode']}" if "mode" in attack else ""
        real = core.attempt_async
        if attack.get("cost"):
            figures = itertools.cycle([-5.0, float("nan"), float("inf")])

            async def lying(kwargs: Any, _real: Any = real) -> Any:
                return dataclasses.replace(await _real(kwargs), litellm_cost_usd=next(figures))

            core.attempt_async = lying
        try:
            gw = DeploymentGateway(cfg, run_dir=run_dir, run_cap_usd=cap_usd)
            with warnings.catch_warnings():  # litellm's pydantic models grumble about fractional counts
                warnings.filterwarnings("ignore", message="Pydantic serializer warnings")
                out, stats = spend_until_refused(gw, lambda i: f"question {i:03d}{suffix}")
        except Exception as exc:
            res.check(f"{name}: the attack ran", False, f"{type(exc).__name__}: {exc}"[:300])
            res.end_run()
            continue
        finally:
            core.attempt_async = real
        ok = [r for r in out if not isinstance(r, LLMError)]
        errors = [r for r in out if isinstance(r, LLMError)]
        spent, bill = int(stats["spent_pico"]), true_bill_pico(server)
        over, under = max(0, spent - cap_pico, bill - cap_pico), max(0, bill - spent)
        worst_over, worst_under = max(worst_over, over), max(worst_under, under)
        # fractional counts: litellm cannot read the reply at all, so the agent gets a
        # server_error, and each such attempt is charged at its reservation
        unreadable = attack.get("mode") == "fracusage"
        expected_errors = {"budget", "server_error"} if unreadable else {"budget"}
        if unreadable:
            res.check(
                f"{name}: every unreadable reply charged a positive amount",
                all(e.cost_usd > 0 for e in errors if e.kind == "server_error"),
                sorted({e.cost_usd for e in errors})[:3],
            )
        else:
            res.check(f"{name}: the provider answered", len(ok) >= (1 if "n" in attack else 2), f"{len(ok)} answers")
        res.check(
            f"{name}: the budget refused in the end, no other error",
            bool(out)
            and isinstance(out[-1], LLMError)
            and out[-1].kind == "budget"
            and {e.kind for e in errors} <= expected_errors,
            sorted({e.kind for e in errors}),
        )
        res.check(
            f"{name}: ledger spend within the cap, nothing reserved, no overrun",
            spent <= cap_pico and stats["reserved_usd"] == 0 and stats["overruns"] == 0,
            f"spent ${pico_to_usd(spent):.6f} of ${cap_usd}, reserved {stats['reserved_usd']}, overruns {stats['overruns']}",
        )
        res.check(
            f"{name}: never billed below what the provider generated",
            spent >= bill,
            f"ledger ${pico_to_usd(spent):.6f}, provider ${pico_to_usd(bill):.6f}",
        )
        res.check(
            f"{name}: every answer charged a positive amount",
            all(r.cost_usd > 0 for r in ok),
            sorted({r.cost_usd for r in ok})[:3],
        )
        if "mode" in attack:
            lied = sum(1 for c in server.log if c.status == 200 and c.mode == attack["mode"])
            answered = len(server.log) if unreadable else len(ok)
            res.check(f"{name}: the provider lied on every answer", lied == answered == len(server.log), (lied, answered))
        elif "n" in attack:
            res.check(
                f"{name}: n choices reached the provider",
                {b.get("n") for b in server.bodies} == {attack["n"]},
                sorted({str(b.get("n")) for b in server.bodies}),
            )
        if "mode" in attack or attack.get("cost"):
            rejected = events(run_dir, USAGE_REJECTED_EVENT)
            # fractional usage is rejected as malformed; every lie is an error event
            res.check(
                f"{name}: each lie recorded as a usage_rejected event",
                len(rejected) == len(ok),
                f"{len(rejected)} events, {len(ok)} answers",
            )
        kinds = ", ".join(f"{k} x{n}" for k, n in sorted(Counter(e.kind for e in errors if e.kind != "budget").items()))
        answered = sum(1 for c in server.log if c.status == 200)
        per_attack.append(
            f"{name} {len(ok)} ok{', ' + kinds if kinds else ''}: ledger ${pico_to_usd(spent):.6f}, "
            f"provider ${pico_to_usd(bill):.6f} for {answered} answers"
        )
        res.end_run()
    res.overspend_usd = pico_to_usd(worst_over)
    res.name = f"cap attacks ({len(attacks)} tried, max overspend ${pico_to_usd(worst_over):.6f})"
    res.notes.append(
        f"{len(attacks)} attacks on a ${cap_usd} cap, max overspend ${pico_to_usd(worst_over):.6f}, "
        f"max under-billed ${pico_to_usd(worst_under):.6f}"
    )
    res.notes += per_attack
    return res


def unreadable_attacks(lab: Lab, cap_usd: float = 0.001, sessions: int = 3) -> ScenarioResult:
    """A provider that answers only HTTP 200s nobody can use, against a small run cap, over
    ``sessions`` gateway sessions on one run folder (a run, then resumes: each replays the ledger
    journal): the provider's own bill never passes the cap, the ledger never bills less than it."""
    from recap.llm import LLMError
    from tests.workers.gateway.test_hostile_provider import config, spend_until_refused, true_bill_pico
    from workers.gateway.core import DeploymentGateway
    from workers.llm.litellm_setup import get_litellm
    from workers.llm.offline.fake_server import UNREADABLE_MODES
    from workers.llm.pricing import pico_to_usd, usd_to_pico

    get_litellm()
    res = ScenarioResult("unreadable-200 cap attacks")
    cap_pico = usd_to_pico(cap_usd)
    # each mode alone, then all of them at random (seeded) from one provider
    attacks: list[tuple[str, dict[str, float]]] = [(m, {m: 1.0}) for m in UNREADABLE_MODES]
    attacks.append(("all modes at random", {m: 1.0 / (len(UNREADABLE_MODES) - i) for i, m in enumerate(UNREADABLE_MODES)}))
    worst_over, worst_under = 0, 0
    per_attack: list[str] = []
    for name, rates in attacks:
        res.begin_run()
        server = lab.server(fault_rates=rates, seed=lab.seed)
        run_dir = _run_dir(lab, "unreadable-" + name.split()[0])
        spent, stats, sent = 0, {}, []
        errors: list[LLMError] = []
        try:
            for session in range(sessions):
                before = len(server.log)
                gw = DeploymentGateway(config(server), run_dir=run_dir, run_cap_usd=cap_usd)
                out, stats = spend_until_refused(gw, lambda i, s=session: f"session {s} question {i:03d}")
                errors += [r for r in out if isinstance(r, LLMError)]
                sent.append(len(server.log) - before)
                res.check(
                    f"{name}: session {session + 1} got no reply it could use",
                    all(isinstance(r, LLMError) for r in out),
                    sorted({type(r).__name__ for r in out}),
                )
        except Exception as exc:
            res.check(f"{name}: the attack ran", False, f"{type(exc).__name__}: {exc}"[:300])
            res.end_run()
            continue
        spent, bill = int(stats["spent_pico"]), true_bill_pico(server)
        over, under = max(0, spent - cap_pico, bill - cap_pico), max(0, bill - spent)
        worst_over, worst_under = max(worst_over, over), max(worst_under, under)
        res.check(
            f"{name}: every reply was a 200 of the attack's modes",
            bool(server.log) and all(c.status == 200 and c.mode in rates for c in server.log),
            sorted({(c.status, c.mode) for c in server.log}),
        )
        res.check(
            f"{name}: each call failed as server_error (charged) or was refused by the budget",
            {e.kind for e in errors} <= {"server_error", "budget"}
            and all(e.cost_usd > 0 for e in errors if e.kind == "server_error"),
            sorted({(e.kind, e.cost_usd > 0) for e in errors}),
        )
        res.check(
            f"{name}: ledger spend within the cap across {sessions} sessions, nothing reserved, no overrun",
            spent <= cap_pico and stats["reserved_usd"] == 0 and stats["overruns"] == 0,
            f"spent ${pico_to_usd(spent):.6f} of ${cap_usd}",
        )
        res.check(
            f"{name}: the provider's bill within the cap and never above the ledger",
            bill <= cap_pico and spent >= bill > 0,
            f"provider ${pico_to_usd(bill):.6f}, ledger ${pico_to_usd(spent):.6f}",
        )
        res.check(f"{name}: the later sessions sent nothing (the charges persisted)", sent[1:] == [0] * (sessions - 1), sent)
        per_attack.append(
            f"{name}: {len(server.log)} replies ({'+'.join(map(str, sent))} per session), "
            f"provider ${pico_to_usd(bill):.6f}, ledger ${pico_to_usd(spent):.6f}"
        )
        res.end_run()
    res.overspend_usd = pico_to_usd(worst_over)
    res.name = f"unreadable-200 cap attacks ({len(attacks)} tried, max overspend ${pico_to_usd(worst_over):.6f})"
    res.notes.append(
        f"{len(attacks)} attacks x {sessions} sessions on a ${cap_usd} cap, max overspend ${pico_to_usd(worst_over):.6f}, "
        f"max under-billed ${pico_to_usd(worst_under):.6f}"
    )
    res.notes += per_attack
    return res


# --------------------------------------------------------------------------------------------
# lock
# --------------------------------------------------------------------------------------------
def lock_race(
    lab: Lab, thread_trials: int = 50, process_trials: int = 10, contenders: int = 8, processes: int = 4
) -> ScenarioResult:
    """Synchronised contenders for one driver lock: exactly one winner per trial."""
    from pipeline.store import LOCK_FILE, RunStore
    from tests.pipeline.test_driver_lock import _contender, _race_threads

    res = ScenarioResult("lock race")
    base = lab.folder("lock-race")
    exact = 0
    for trial in range(thread_trials):
        res.begin_run()
        folder = base / f"t{trial}"
        if trial % 2:  # a stale lock file left by a driver that died
            folder.mkdir()
            (folder / LOCK_FILE).write_text(json.dumps({"pid": 999999999, "host": socket.gethostname()}))
        try:
            winners = _race_threads(folder, contenders)
        except AssertionError as exc:  # a refusal that is not the one-line "in use" message
            res.check(f"thread trial {trial}: every loser refused with one line", False, str(exc)[:200])
            res.end_run()
            continue
        good = res.check(f"thread trial {trial}: exactly 1 winner of {contenders}", len(winners) == 1, len(winners))
        holder = RunStore(folder).lock_holder()
        res.check(
            f"thread trial {trial}: the lock names the winner", holder is not None and holder.get("pid") == os.getpid(), holder
        )
        for w in winners:
            w.release_lock()
        res.check(f"thread trial {trial}: free after release", RunStore(folder).lock_holder() is None)
        exact += int(good)
        res.end_run()
    ctx = mp.get_context("fork")
    for trial in range(process_trials):
        res.begin_run()
        folder = base / f"p{trial}"
        barrier, results, hold = ctx.Barrier(processes), ctx.Queue(), ctx.Event()
        procs = [ctx.Process(target=_contender, args=(str(folder), barrier, results, hold)) for _ in range(processes)]
        for p in procs:
            p.start()
        got: list[str] = []
        try:
            for _ in procs:
                got.append(results.get(timeout=30))
        except queue.Empty:
            pass
        hold.set()
        for p in procs:
            p.join(30)
            if p.is_alive():
                p.kill()
                p.join(5)
        good = res.check(
            f"process trial {trial}: exactly 1 winner of {processes}",
            sorted(got) == ["refused"] * (processes - 1) + ["won"],
            sorted(got),
        )
        res.check(f"process trial {trial}: free once the processes ended", RunStore(folder).lock_holder() is None)
        exact += int(good)
        res.end_run()
    n = thread_trials + process_trials
    res.name = f"lock race ({n} trials, {'1 winner each' if exact == n else f'{exact} with 1 winner'})"
    res.notes.append(
        f"{n} trials, {exact} with exactly 1 winner ({thread_trials} x {contenders} threads, "
        f"{process_trials} x {processes} processes)"
    )
    return res
