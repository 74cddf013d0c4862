"""FEVER's Wikipedia under attack (issue 35 items 7-10): hostile pages stay bounded, tampered
snapshots are refused.

The live attacks are those of ``tests/workers/envs/fever/hostile.py`` (real loopback servers:
a page that drips, its headers dripped, slow 500s, a 54 MB page, a 1 GiB gzip bomb, redirects to
another host, port or scheme, a redirect loop, a same-host redirect); the snapshot attacks those
of ``tests/workers/envs/fever/tampering.py`` (a sealed run folder, then one change), each also
played through ``recap run``: exit 2, one line, nothing written. ``test_hostile_pages.py`` and
``test_snapshot_manifest.py`` assert them one by one.
"""

from __future__ import annotations

import contextlib
import io
import json
from collections.abc import Callable
from pathlib import Path

from tests.pipeline.chaos.harness import Lab, ScenarioResult
from tests.workers.envs.fever import hostile, tampering
from tests.workers.envs.fever.hostile import DEADLINE_S, SLACK_S, MiB, Outcome

#: peak Python memory a refused big answer may cost (the 5 MiB cap, a chunk, the decoder's window)
MEMORY_BOUND = 16 * MiB


def _timed_out(out: Outcome) -> bool:
    return out.kind == "timeout" and out.elapsed_s <= DEADLINE_S + SLACK_S and not out.rows


def _too_large(out: Outcome) -> bool:
    return out.kind == "too_large" and not out.rows and out.peak_bytes < MEMORY_BOUND


def _kept_home(out: Outcome) -> bool:
    return out.kind == "redirect" and out.hits.get("other", 0) == 0 and not out.rows and len(out.acquired) == 1


LIVE: list[tuple[str, Callable[[], Outcome], Callable[[Outcome], bool]]] = [
    ("drip: headers, then a byte every 0.5 s (2 s deadline)", hostile.attack_drip, _timed_out),
    ("drip: the headers themselves dripped", hostile.attack_drip_headers, _timed_out),
    (
        "slow 500s: retries stop at the deadline",
        hostile.attack_slow_retries,
        lambda o: o.kind == "unavailable" and o.elapsed_s <= DEADLINE_S + SLACK_S,
    ),
    ("big page: 54 MB with its Content-Length", lambda: hostile.attack_big_page(54 * MiB, with_length=True), _too_large),
    ("big page: 54 MB until the connection closes", lambda: hostile.attack_big_page(54 * MiB, with_length=False), _too_large),
    ("gzip bomb: 1 MB that expands to 1 GiB", lambda: hostile.attack_gzip_bomb(1024 * MiB), _too_large),
    ("cross-host redirect (127.0.0.2)", hostile.attack_cross_host, _kept_home),
    ("cross-port redirect", hostile.attack_cross_port, _kept_home),
    ("scheme change redirect (https)", hostile.attack_scheme_change, _kept_home),
    (
        "too many hops (a same-host redirect loop)",
        hostile.attack_redirect_loop,
        lambda o: o.kind == "redirect" and o.hits == {"wiki": 6} and len(o.acquired) == 6,
    ),
    (
        "same-host redirect: served, each hop rate-limited",
        hostile.attack_same_host_redirect,
        lambda o: o.kind is None and len(o.acquired) == 2 and hostile.same_host_hops_wait(2.0) == [0.5],
    ),
]


def _recap_run(folder: Path, snapshot: Path, claims: Path) -> tuple[int, list[str], bool]:
    """``recap run`` of a one-claim FEVER sweep answering from ``snapshot``: (exit, stderr lines, output written?)."""
    from pipeline.cli import main

    spec = folder / "sweep.yaml"
    out = folder / "out"
    spec.write_text(
        f"run: replay\noutput: {out}\nmodels:\n  - model: offline/expert\nmethods:\n  - method: react\n"
        f'environments:\n  - benchmark: fever\n    tasks: [all]\n    options: {{data_dir: "{claims}", wikipedia: "snapshot:{snapshot}"}}\n'
    )
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["run", str(spec), "--progress", "off"])
    return code, err.getvalue().strip().splitlines(), out.exists()


def wiki(lab: Lab) -> ScenarioResult:
    res = ScenarioResult("FEVER Wikipedia: hostile pages, tampered snapshots")
    res.begin_run()
    tried = held = 0
    for name, attack, ok in LIVE:
        out = attack()
        tried += 1
        held += res.check(name, ok(out), out.detail())
    root = lab.folder("wiki")
    claims = root / "claims"
    claims.mkdir(exist_ok=True)
    claim = {"id": 1001, "verifiable": "VERIFIABLE", "label": "SUPPORTS", "claim": "Alpha is a letter."}
    (claims / "paper_dev.jsonl").write_text(json.dumps(claim) + "\n", encoding="utf-8")
    intact = tampering.sealed_run(root / "intact")
    res.check("an untampered sealed snapshot is served", tampering.load(intact) is None)
    attacks: dict[str, Callable[[Path], None] | None] = {**tampering.TAMPERINGS, "old snapshot (no manifest)": None}
    for i, (name, tamper) in enumerate(attacks.items()):
        case = root / f"case-{i:02d}"
        run = tampering.sealed_run(case / "snap", sealed=tamper is not None)
        if tamper is not None:
            tamper(run)
        refusal = tampering.load(run)
        code, lines, wrote = _recap_run(case, run, claims)
        ok = refusal is not None and code == 2 and len(lines) == 1 and not wrote
        tried += 1
        held += res.check(f"snapshot: {name}", ok, f"exit {code}, {len(lines)} line(s), wrote {wrote}: {refusal}")
    res.notes.append(f"{held}/{tried} held")
    res.end_run()
    return res
