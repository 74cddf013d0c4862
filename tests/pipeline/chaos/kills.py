"""Processes killed with SIGKILL mid-run: an episode worker, the gateway, the driver.

* worker: 20 episodes (offline/expert and the fake server), workers killed at random points
  of random attempts; every finished episode keeps its terminal row and records, no unit ends
  without one, none gets two.
* gateway: the GatewayActor and then the BudgetActor killed while calls are in flight under a
  binding run cap; both come back (Ray restarts them), calls in flight are retried on the new
  incarnation, the spend is restored from the ledger journal, and the provider's own bill never
  passes the cap. A resume with a higher cap then finishes every unit.
* driver: ``recap run`` killed at a random moment (once or twice, the second time during
  ``recap resume``), then ``recap resume``: the final tables equal an uninterrupted run's, and
  no unit whose terminal row was on disk is paid for again.
* sink: the sink actor killed mid-run (once or twice); it comes back and the run goes on - or,
  with its restarts used up, the driver stops at once - then ``recap resume``: lost 0,
  duplicated 0, no unit whose episode finished before a kill run or paid again.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import (
    Lab,
    ScenarioResult,
    attempt_of,
    blocks,
    calls_by_episode,
    events,
    fake_model,
    journal,
    journal_spend,
    provider_bill_usd,
    reserved_episodes,
    rows,
    run_driver,
    sweep,
    terminal,
    unit_of,
    wait_until,
)

_COMPARED = ("end_reason", "success", "steps", "llm_calls", "prompt_tokens", "completion_tokens", "cost_usd")


def _actor_pid(actor: Any) -> int:
    import ray

    return int(ray.get(actor.__ray_call__.remote(lambda self: os.getpid()), timeout=30))


def _records_complete(res: ScenarioResult, out: Path, episode_ids: set[str]) -> None:
    """Every finished episode's llm_calls rows and messages reached the run folder."""
    calls = calls_by_episode(out)
    eps = {r["episode_id"]: r for r in rows(out, "episodes")}
    messages = {r["episode_id"] for r in rows(out, "messages", ["episode_id"])}
    short = [e for e in episode_ids if len(calls.get(e, [])) != eps[e]["llm_calls"]]
    res.check("each finished episode has one llm_calls row per call", not short, short[:3])
    missing = sorted(e for e in episode_ids if e not in messages)
    res.check("each finished episode has its messages", not missing, missing[:3])


# --------------------------------------------------------------------------------------------
def worker_kill(lab: Lab, runs: int = 1, units: int = 20) -> ScenarioResult:
    """SIGKILL episode workers at random points of 20 episodes."""

    from pipeline.driver import Hooks

    res = ScenarioResult(f"worker SIGKILL ({units} episodes)")
    lab.ray_address()
    server = lab.server(latency_s=0.12, prefix_memory=0)
    for r in range(runs):
        res.begin_run()
        rng = lab.rng(f"worker-kill-{r}")
        out = lab.folder(f"worker-kill-{r}") / "run"
        models = "  - model: offline/expert\n" + fake_model(server.base_url)
        text = sweep(out, models, blocks(units // 2), workers=4, llm_calls=10, extra="max_attempts: 3\n")
        kills: list[dict[str, Any]] = []
        returned: list[str] = []
        lock = threading.Lock()

        def on_dispatch(unit: Any, attempt: int, actor: Any) -> None:
            # first attempts only, and only while that attempt runs: with max_attempts 3 no unit
            # can run out of attempts, so every unit must end with a normal terminal row
            with lock:
                if attempt > 1 or len(kills) >= 8 or rng.random() > 0.45:
                    return
                kill = {"unit": unit.unit_id, "attempt": attempt, "delay": rng.uniform(0.0, 1.5)}
                kills.append(kill)

            def go() -> None:
                time.sleep(kill["delay"])
                if f"{unit.unit_id}-{attempt}" in returned:
                    kill["error"] = "returned first"
                    return
                try:
                    pid = _actor_pid(actor)
                    os.kill(pid, signal.SIGKILL)
                    kill["pid"] = pid
                except Exception as exc:  # already dead (another kill, or replaced)
                    kill["error"] = type(exc).__name__

            threading.Thread(target=go, daemon=True).start()

        def on_result(unit: Any, attempt: int, out_: Any) -> None:
            if out_.crash is None:
                returned.append(f"{unit.unit_id}-{attempt}")

        summary, _ = run_driver(text, hooks=Hooks(on_dispatch=on_dispatch, on_result=on_result))
        time.sleep(0.5)
        term = terminal(out)
        landed = [k for k in kills if "pid" in k]
        lost_events = events(out, "worker_lost")
        finished_ids = {r["episode_id"] for r in term.rows}
        res.check(
            "run exits 0 with every unit done",
            summary.exit_code() == 0 and not term.lost,
            f"exit {summary.exit_code()}, not done {len(term.lost)}",
        )
        res.check(
            "every returned episode has its terminal row", set(returned) <= finished_ids, sorted(set(returned) - finished_ids)[:3]
        )
        res.check(
            "no terminal row for an attempt that never returned",
            finished_ids <= set(returned),
            sorted(finished_ids - set(returned))[:3],
        )
        res.check(
            "one worker_lost event per worker replaced",
            len(lost_events) == summary.worker_restarts and summary.worker_restarts <= len(landed),
            f"{len(lost_events)} events, {summary.worker_restarts} restarts, {len(landed)} kills",
        )
        res.check("kills landed", len(landed) >= 1 and summary.worker_restarts >= 1, f"{len(landed)} kills")
        _records_complete(res, out, finished_ids)
        orphans = {r["episode_id"] for r in rows(out, "messages", ["episode_id"])} - finished_ids
        res.lost += len(term.lost) + len(set(returned) - finished_ids)
        res.duplicated += term.duplicated
        res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
        res.notes.append(
            f"{len(landed)} kills, {summary.worker_restarts} workers replaced, {len(orphans)} killed attempts left orphan rows"
        )
        res.end_run()
    return res


# --------------------------------------------------------------------------------------------
def _calibrate(lab: Lab, server: Any, name: str) -> float:
    """Spend of one episode of the scenario's shape (to size a cap that binds mid-run)."""
    out = lab.folder(name) / "calibrate"
    run_driver(sweep(out, fake_model(server.base_url), blocks(1), llm_calls=6, workers=1))
    return sum(r["cost_usd"] for r in rows(out, "llm_calls"))


def gateway_kill(lab: Lab, runs: int = 1, units: int = 12) -> ScenarioResult:
    """SIGKILL the GatewayActor, then the BudgetActor, mid-run under a binding run cap."""
    import ray

    from pipeline.gateway_backend import GatewayBackend
    from pipeline.spec import parse_spec

    res = ScenarioResult("gateway + budget actors SIGKILL, capped")
    lab.ray_address()
    for r in range(runs):
        res.begin_run()
        rng = lab.rng(f"gateway-kill-{r}")
        server = lab.server(latency_s=0.25, prefix_memory=0)
        per_episode = _calibrate(lab, server, f"gateway-kill-{r}")
        cap = round(per_episode * units * 0.6, 6)
        out = lab.folder(f"gateway-kill-{r}") / "run"
        text = sweep(out, fake_model(server.base_url), blocks(units), llm_calls=6, workers=3, extra=f"run_cap_usd: {cap}\n")
        server.reset()
        backend = GatewayBackend(parse_spec(text))
        plan = {"gateway": rng.uniform(0.15, 0.35), "budget": rng.uniform(0.45, 0.65)}
        seen: dict[str, Any] = {}

        def killer() -> None:
            for target in ("gateway", "budget"):
                if not wait_until(lambda: backend.budget is not None and backend.actors, 120, 0.05):
                    return
                actor = backend.budget if target == "budget" else next(iter(backend.actors.values()))
                try:
                    pid = _actor_pid(actor)
                    if not wait_until(
                        lambda: ray.get(backend.budget.stats.remote())["spent_usd"] >= plan[target] * cap, 120, 0.05
                    ):
                        return
                    before = ray.get(backend.budget.stats.remote())
                    inflight = ray.get(next(iter(backend.actors.values())).stats.remote())["inflight"]
                    os.kill(pid, signal.SIGKILL)
                    seen[target] = {
                        "pid": pid,
                        "t": time.monotonic(),
                        "arrivals": len(server.log),
                        "spent_pico": before["spent_pico"],
                        "inflight": inflight,
                    }
                    after = ray.get(backend.budget.stats.remote(), timeout=120)  # waits for the restart
                    seen[target]["after_pico"] = after["spent_pico"]
                    seen[target]["new_pid"] = _actor_pid(actor)
                except Exception as exc:
                    seen.setdefault(target, {})["error"] = f"{type(exc).__name__}: {exc}"
                    return

        t = threading.Thread(target=killer, daemon=True)
        t.start()
        summary, _ = run_driver(text, backend=backend)
        t.join(30)
        term = terminal(out)
        bill = provider_bill_usd(server)
        ledger_usd = sum(journal_spend(journal(out)).values()) / 1e12
        table_usd = sum(r["cost_usd"] for r in rows(out, "llm_calls"))
        for target in ("gateway", "budget"):
            s = seen.get(target, {})
            res.check(f"{target} actor killed and restarted", "new_pid" in s and s["new_pid"] != s["pid"], s)
            res.check(f"{target} kill: spend restored, never lower", s.get("after_pico", -1) >= s.get("spent_pico", 0), s)
        res.check(
            "calls went on after the kills",
            "budget" in seen and len(server.log) > seen["budget"].get("arrivals", 10**9),
            len(server.log),
        )
        errors = [r["episode_id"] for r in term.rows if r["end_reason"] == "llm_error"]
        res.check("no episode ended llm_error because of the kills", not errors, errors[:3])
        restored = [e for e in journal(out) if e.get("status") == "orphaned"]
        res.check("open reservations of the dead actors charged from the journal", len(restored) >= 1, len(restored))
        res.check("the cap bound (run stopped, exit 3)", summary.exit_code() == 3 and summary.stopped, summary.stopped)
        over = max(bill, ledger_usd, table_usd) - cap
        res.check(
            "provider bill, ledger and llm_calls within the cap",
            over <= 1e-12,
            f"bill ${bill:.6f}, ledger ${ledger_usd:.6f}, table ${table_usd:.6f}, cap ${cap:.6f}",
        )
        res.add_overspend(over)
        # a restart that found reservations of its dead predecessor says so in the events table
        kinds = {e["kind"] for e in events(out) if e["kind"] in ("orphans_charged", "ledger_restored")}
        expected = {
            k
            for k, target in (("orphans_charged", "gateway"), ("ledger_restored", "budget"))
            if seen.get(target, {}).get("inflight", 0) > 0
        }
        res.check("restarts visible in events", expected and expected <= kinds, f"{sorted(kinds)} (expected {sorted(expected)})")
        # finish with a higher cap: every unit done exactly once
        summary2, _ = run_driver(text, overrides={"run_cap_usd": cap * 10})
        term = terminal(out)
        res.check(
            "resume with a higher cap finishes every unit",
            summary2.exit_code() == 0 and not term.lost,
            f"exit {summary2.exit_code()}, not done {len(term.lost)}",
        )
        res.lost += len(term.lost) + len(errors)
        res.duplicated += term.duplicated
        res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
        res.notes.append(
            f"cap ${cap:.4f}: provider billed ${bill:.4f}, ledger ${ledger_usd:.4f}; "
            f"{len(restored)} in-flight reservations charged at worst case"
        )
        res.end_run()
    return res


# --------------------------------------------------------------------------------------------
def _kill_at(proc: subprocess.Popen, journal_file: Path, after_s: float) -> bool:
    """SIGKILL ``proc`` ``after_s`` seconds after the run's next model call was reserved (the
    sweep is under way; the CLI takes a few seconds to start), unless it ended first; True
    when killed."""
    size = journal_file.stat().st_size if journal_file.exists() else 0
    wait_until(lambda: proc.poll() is not None or (journal_file.exists() and journal_file.stat().st_size > size), 180, 0.05)
    try:
        proc.wait(timeout=after_s)
        return False
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        return True


def driver_kill(lab: Lab, runs: int = 2, units: int = 12) -> ScenarioResult:
    """SIGKILL ``recap run`` / ``recap resume`` at random moments, then resume to the end."""
    res = ScenarioResult("driver SIGKILL + recap resume")
    address = lab.ray_address()
    server = lab.server(latency_s=0.2, prefix_memory=0)
    base = lab.folder("driver-kill")
    ref_out = base / "reference"
    run_driver(sweep(ref_out, fake_model(server.base_url), blocks(units), run="driver-kill", workers=3, llm_calls=8))
    stamps = [e["t"] for e in journal(ref_out)]
    active_s = max(stamps) - min(stamps)  # first call reserved .. last one settled
    reference = terminal(ref_out).completed
    ref_paid = journal_spend(journal(ref_out))
    ref_spend = {u: ref_paid[r["episode_id"]] for u, r in reference.items()}  # pico, as the ledger settled it
    for r in range(runs):
        res.begin_run()
        rng = lab.rng(f"driver-kill-{r}")
        out = base / f"run-{r}"
        spec_file = base / f"sweep-{r}.yaml"
        spec_file.write_text(sweep(out, fake_model(server.base_url), blocks(units), run="driver-kill", workers=3, llm_calls=8))
        common = ["--address", address, "--progress", "off"]
        kills = 1 + int(rng.random() < 0.5)
        snapshots: list[dict[str, int]] = []  # per kill: unit -> completed attempt on disk
        kill_points: list[str] = []
        for k in range(kills):
            started = (out / "run.json").exists()
            args = ["resume", str(out)] if started else ["run", str(spec_file)]
            proc = lab.cli(args + common, env=lab.env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            # the first kill of run r falls in the r-th slice of the sweep (runs spread their kill
            # points from early to late); a second one anywhere in the resume
            lo, hi = (0.05 + 0.9 * r / runs, 0.05 + 0.9 * (r + 1) / runs) if k == 0 else (0.05, 0.95)
            delay = rng.uniform(lo, hi) * active_s
            killed = _kill_at(proc, out / "gateway" / "ledger.jsonl", delay)
            if not killed:
                break
            time.sleep(1.5)  # Ray reaps the dead driver's actors (sink, gateway, workers)
            if (out / "plan.json").exists():
                snapshots.append({u: row["attempt"] for u, row in terminal(out).completed.items()})
                kill_points.append(f"{delay:.1f}s of ~{active_s:.0f}s ({len(snapshots[-1])}/{units} done)")
        final = (
            lab.cli(["resume", str(out)] + common, env=lab.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
            if (out / "run.json").exists()
            else lab.cli(
                ["run", str(spec_file)] + common, env=lab.env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
            )
        )
        try:
            output, _ = final.communicate(timeout=300)
        except subprocess.TimeoutExpired:
            final.kill()
            output, _ = final.communicate()
        res.check("final resume exits 0", final.returncode == 0, f"exit {final.returncode}: {output.strip().splitlines()[-1:]}")
        term = terminal(out)
        done = term.completed
        res.check("same unit set as an uninterrupted run", set(done) == set(reference), f"{len(done)} vs {len(reference)}")
        diff = [u for u in reference if u in done and any(done[u][c] != reference[u][c] for c in _COMPARED)]
        res.check("each unit's terminal row equals the uninterrupted run's", not diff, diff[:3])
        entries = journal(out)
        paid = journal_spend(entries)
        reserved = reserved_episodes(entries)
        repaid_units, repaid_pico = set(), 0
        for snap in snapshots:
            for unit, attempt in snap.items():
                later = [e for e in reserved if unit_of(e) == unit and attempt_of(e) > attempt]
                if later:
                    repaid_units.add(unit)
                    repaid_pico += sum(paid.get(e, 0) for e in later)
        res.check("no unit completed on disk was paid for again", not repaid_units, sorted(repaid_units)[:3])
        res.add_overspend(repaid_pico / 1e12)
        # what each completing attempt paid, from the fsync'd ledger journal (the llm_calls rows
        # of the last second before a kill may be lost with the gateway's write buffer)
        off = [u for u, row in done.items() if paid.get(row["episode_id"], 0) != ref_spend.get(u, -1)]
        res.check("each completed attempt paid once, at the uninterrupted run's cost (ledger)", not off, off[:3])
        calls = calls_by_episode(out)
        served = {c["served_from"] for row in done.values() for c in calls.get(row["episode_id"], [])}
        res.check("completed attempts served by the provider (no replays)", served <= {"provider"}, served)
        missing_rows = sum(max(0, row["llm_calls"] - len(calls.get(row["episode_id"], []))) for row in done.values())
        wasted = sum(v for e, v in paid.items() if e not in {row["episode_id"] for row in done.values()}) / 1e12
        # attempts that finished (every call paid) but whose terminal row never reached the disk
        full = {u: 0 for u in reference}
        for e in reserved:
            u = unit_of(e)
            n_ok = len(
                {
                    x["key"]
                    for x in entries
                    if x.get("op") == "settle" and x.get("status") == "ok" and x["key"].rsplit("#", 1)[0] == e
                }
            )
            if u in reference and n_ok >= reference[u]["llm_calls"]:
                full[u] += 1
        redone = sum(1 for n in full.values() if n > 1)
        res.lost += len(term.lost)
        res.duplicated += term.duplicated
        res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
        res.check("the driver was killed mid-run", bool(kill_points), kill_points)
        res.notes.append(
            f"run {r}: killed at {', '.join(kill_points) or '-'}; ${wasted:.4f} paid for "
            f"killed attempts; {redone} finished episodes re-run (terminal row not yet on disk); "
            f"{missing_rows} llm_calls rows lost with the gateway buffer"
        )
        res.end_run()
    return res


# --------------------------------------------------------------------------------------------
def _sink_killer(driver: Any, out: Path, at_rows: list[int], seen: list[dict[str, Any]]) -> threading.Thread:
    """SIGKILL the driver's sink actor each time the run folder holds ``at_rows[i]`` terminal
    rows; ``seen`` gets, per kill, the pid and the units completed on disk at that moment."""

    def go() -> None:
        for n in at_rows:
            if not wait_until(lambda: driver.sink is not None and len(terminal_rows(out)) >= n, 180, 0.05):
                return
            kill: dict[str, Any] = {"at_rows": n}
            seen.append(kill)
            try:
                pid = _actor_pid(driver.sink)
                kill["done"] = {r["unit_id"]: r["attempt"] for r in terminal_rows(out)}
                os.kill(pid, signal.SIGKILL)
                kill["pid"] = pid
                kill["new_pid"] = _actor_pid(driver.sink)  # waits for the restart (when there is one)
            except Exception as exc:
                kill["error"] = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
                return

    t = threading.Thread(target=go, daemon=True)
    t.start()
    return t


def terminal_rows(out: Path) -> list[dict[str, Any]]:
    return rows(out, "episodes", ["unit_id", "attempt", "episode_id"]) if (out / "plan.json").exists() else []


def sink_kill(lab: Lab, runs: int = 1, units: int = 12, restarts: bool = True) -> ScenarioResult:
    """SIGKILL the sink actor mid-run (once or twice), then ``recap resume``.

    ``restarts``: the sink comes back (Ray restarts it, the senders' calls are retried) and the
    run goes on; without, the driver stops at once, writes what finished itself, and the
    resume runs only what was never written. Either way: lost 0, duplicated 0, no unit whose
    episode finished before a kill is run again, no finished unit paid twice."""
    import workers.sink
    from pipeline.driver import Driver, Hooks, prepare
    from pipeline.errors import PipelineError
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec

    name = "sink SIGKILL" + ("" if restarts else " (no restart: driver stops)")
    res = ScenarioResult(f"{name} + recap resume")
    lab.ray_address()
    server = lab.server(latency_s=0.15, prefix_memory=0)
    base = lab.folder("sink-kill" if restarts else "sink-gone")
    ref_out = base / "reference"
    run_driver(sweep(ref_out, fake_model(server.base_url), blocks(units), run="sink-kill", workers=3, llm_calls=6))
    reference = terminal(ref_out).completed
    ref_paid = journal_spend(journal(ref_out))
    ref_spend = {u: ref_paid[r["episode_id"]] for u, r in reference.items()}
    old_restarts = workers.sink.SINK_MAX_RESTARTS
    for r in range(runs):
        res.begin_run()
        rng = lab.rng(f"sink-kill-{restarts}-{r}")
        out = base / f"run-{r}"
        text = sweep(out, fake_model(server.base_url), blocks(units), run="sink-kill", workers=3, llm_calls=6)
        first = rng.randint(1, units // 3)
        at_rows = [first] + ([first + rng.randint(2, units // 3)] if restarts and rng.random() < 0.5 else [])
        dispatched: list[tuple[str, int]] = []
        hooks = Hooks(on_dispatch=lambda u, a, actor: dispatched.append((u.unit_id, a)))
        workers.sink.SINK_MAX_RESTARTS = old_restarts if restarts else 0
        try:
            spec = parse_spec(text, "sweep.yaml")
            driver = Driver(prepare(spec, text), make_backend(spec), progress="off", hooks=hooks)
            seen: list[dict[str, Any]] = []
            killer = _sink_killer(driver, out, at_rows, seen)
            error = None
            try:
                summary = driver.run()
            except PipelineError as exc:
                summary, error = driver.summary, str(exc)
            killer.join(60)
        finally:
            workers.sink.SINK_MAX_RESTARTS = old_restarts
        landed = [k for k in seen if "pid" in k]
        res.check("the sink was killed mid-run", landed and all(len(k["done"]) < units for k in landed), seen)
        if restarts:
            res.check("the sink came back after each kill", all(k.get("new_pid") not in (None, k["pid"]) for k in landed), seen)
            res.check(
                "the run went on to the end (exit 0)", error is None and summary.exit_code() == 0, error or summary.exit_code()
            )
        else:
            res.check(
                "the driver stopped at once with one line naming recap resume",
                error is not None and "recap resume" in error and "\n" not in error,
                error,
            )
        res.check(
            "the sink's death was not read as worker deaths",
            summary.worker_restarts == 0 and not events(out, "worker_lost"),
            summary.worker_restarts,
        )
        on_disk = {row["unit_id"] for row in terminal_rows(out)}
        before = set(on_disk)
        again: list[str] = []
        summary2, _ = run_driver(text, hooks=Hooks(on_dispatch=lambda u, a, actor: again.append(u.unit_id)))
        term = terminal(out)
        done = term.completed
        res.check(
            "resume exits 0 with every unit done",
            summary2.exit_code() == 0 and not term.lost,
            f"exit {summary2.exit_code()}, not done {len(term.lost)}",
        )
        res.check(
            "resume ran exactly the units without a terminal row",
            set(again) == set(reference) - before,
            f"ran {len(set(again))}, missing {len(set(reference) - before)}",
        )
        res.check("same unit set as an uninterrupted run", set(done) == set(reference), f"{len(done)} vs {len(reference)}")
        diff = [u for u in reference if u in done and any(done[u][c] != reference[u][c] for c in _COMPARED)]
        res.check("each unit's terminal row equals the uninterrupted run's", not diff, diff[:3])
        entries = journal(out)
        paid = journal_spend(entries)
        reserved = reserved_episodes(entries)
        repaid_units, repaid_pico = set(), 0
        for kill in landed:
            for unit, attempt in kill["done"].items():
                later = [e for e in reserved if unit_of(e) == unit and attempt_of(e) > attempt]
                if later:
                    repaid_units.add(unit)
                    repaid_pico += sum(paid.get(e, 0) for e in later)
        res.check("no unit whose episode finished before a kill was run again", not repaid_units, sorted(repaid_units)[:3])
        res.add_overspend(repaid_pico / 1e12)
        off = [u for u, row in done.items() if paid.get(row["episode_id"], 0) != ref_spend.get(u, -1)]
        res.check("each completed attempt paid once, at the uninterrupted run's cost (ledger)", not off, off[:3])
        if restarts:
            res.check(
                "one attempt per unit: nothing re-run at all",
                all(attempt_of(e) == 1 for e in reserved),
                sorted(e for e in reserved if attempt_of(e) != 1)[:3],
            )
        _records_complete(res, out, {row["episode_id"] for row in done.values()})
        res.lost += len(term.lost)
        res.duplicated += term.duplicated
        res.check("lost 0, duplicated 0", not term.lost and term.duplicated == 0, (len(term.lost), term.duplicated))
        res.notes.append(
            f"run {r}: sink killed at {[k['at_rows'] for k in landed]} terminal rows; "
            f"{len(before)}/{units} units on disk after the first session"
        )
        res.end_run()
    return res
