"""A run folder with broken Parquet part files: reported and skipped, never fatal; resume
re-runs exactly the units whose terminal rows were lost.

Damage done to a finished run (the kinds a crash, a full disk or a bad copy leave):

* ``episodes``: one part truncated to half its size (its terminal rows are gone);
* ``messages``: one part overwritten with bytes that look like Parquet (magic at both ends);
* ``steps``: one empty part;
* ``events``: a readable Parquet file with the wrong columns;
* ``tree_nodes``: a half-written temp file (``.tmp-part-...``) left by a killed writer.

``recap status``, ``recap sql``, ``recap report`` and ``recap show`` must exit 0 (or with a
one-line error), naming every unreadable part; ``recap resume`` must re-run the units whose
terminal rows were in the truncated part, and only those.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from tests.pipeline.chaos.harness import (
    Lab,
    ScenarioResult,
    blocks,
    calls_by_episode,
    run_driver,
    sweep,
    terminal,
)


def cli(*args: str) -> tuple[int, str, str]:
    """``recap ARGS`` in this process: (exit status, stdout, stderr); a traceback is a failure."""
    from pipeline.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(list(args))
        except SystemExit as exc:
            code = int(exc.code or 0)
        except Exception as exc:  # noqa: BLE001 - the scenario reports it
            return 99, out.getvalue(), f"{type(exc).__name__}: {exc}"
    return code, out.getvalue(), err.getvalue()


def damage(out: Path) -> dict[str, Any]:
    """Break one part file of several tables (see the module docstring); returns what was hit."""
    hit: dict[str, Any] = {}
    eps = sorted((out / "episodes").glob("part-*.parquet"), key=lambda p: -pq.read_metadata(p).num_rows)
    victim = eps[0]
    hit["lost_units"] = set(pq.read_table(victim, columns=["unit_id"]).column("unit_id").to_pylist())
    data = victim.read_bytes()
    victim.write_bytes(data[: len(data) // 2])
    hit["episodes"] = victim
    msgs = sorted((out / "messages").glob("part-*.parquet"))[0]
    hit["message_episodes"] = set(pq.read_table(msgs, columns=["episode_id"]).column("episode_id").to_pylist())
    msgs.write_bytes(b"PAR1" + bytes(range(256)) * 8 + b"PAR1")
    hit["messages"] = msgs
    steps = sorted((out / "steps").glob("part-*.parquet"))[0]
    steps.write_bytes(b"")
    hit["steps"] = steps
    wrong = out / "events" / "part-zzforeign-000001.parquet"
    wrong.parent.mkdir(exist_ok=True)
    pq.write_table(pa.table({"something": ["else"], "n": [1]}), wrong)
    hit["events"] = wrong
    nodes = sorted((out / "tree_nodes").glob("part-*.parquet"))
    temp = out / "tree_nodes" / ".tmp-part-killed-000009.parquet"
    temp.write_bytes(nodes[0].read_bytes()[:100] if nodes else b"PAR1")
    hit["temp"] = temp
    return hit


def corrupt_parts(lab: Lab) -> ScenarioResult:
    res = ScenarioResult("corrupt / truncated Parquet parts")
    res.begin_run()
    lab.ray_address()
    out = lab.folder("corrupt") / "run"
    text = sweep(out, "  - model: offline/expert\n", blocks(10), method="recap", llm_calls=40, workers=3)
    summary, _ = run_driver(text)
    res.check("the run finished", summary.exit_code() == 0, summary.exit_code())
    before = terminal(out)
    calls_before = {e: len(c) for e, c in calls_by_episode(out).items()}
    # let the sink write more than one part per table, so that damage hits a part, not all
    hit = damage(out)
    broken = [hit[k] for k in ("episodes", "messages", "steps", "events")]

    code, stdout, stderr = cli("status", str(out))
    res.check("recap status exits 0", code == 0, stderr.strip()[-300:])
    named = [p for p in broken if str(p) not in stdout]
    res.check("recap status names every unreadable part", not named, named)
    n_left = len(before.plan) - len(hit["lost_units"])
    res.check(
        "recap status counts the units still done",
        f"units {n_left}/{len(before.plan)} done" in stdout,
        [line for line in stdout.splitlines() if line.startswith("units ")],
    )
    res.check("a writer's leftover temp file is ignored", str(hit["temp"]) not in stdout)

    code, stdout, stderr = cli("sql", str(out), "select count(*) as n from episodes", "--csv")
    res.check(
        "recap sql reads what is readable",
        code == 0 and stdout.splitlines() == ["n", str(n_left)],
        (code, stdout.strip(), stderr.strip()[-200:]),
    )
    report_dir = out.parent / "report"
    code, stdout, stderr = cli("report", str(out), "--out", str(report_dir), "--format", "md")
    md = (report_dir / "report.md").read_text() if (report_dir / "report.md").exists() else ""
    # (the reports read parts by column name, for older schema versions: a foreign-schema part
    # is merged with empty columns there, not skipped; truncated and corrupt ones are skipped)
    corrupt = [hit[k] for k in ("episodes", "messages", "steps")]
    res.check(
        "recap report exits 0 and lists the truncated / corrupt parts",
        code == 0 and "Unreadable part files were skipped" in md and all(str(p) in md for p in corrupt),
        (code, [str(p) for p in corrupt if str(p) not in md]),
    )
    victim_episode = sorted(hit["message_episodes"])[0]
    code, stdout, stderr = cli("show", str(out), victim_episode)
    res.check(
        "recap show on an episode whose messages were lost: no traceback",
        code in (0, 2) and len(stderr.strip().splitlines()) <= 1 + len(broken),
        (code, stderr.strip()[-300:]),
    )

    code, stdout, stderr = cli("resume", str(out), "--progress", "off")
    res.check("recap resume exits 0", code == 0, stderr.strip()[-300:])
    after = terminal(out)
    rerun = {r["unit_id"] for r in after.rows if r["attempt"] > 1}
    res.check(
        "resume re-ran exactly the units whose terminal rows were lost",
        rerun == hit["lost_units"],
        f"re-ran {len(rerun)}, lost {len(hit['lost_units'])}",
    )
    new_calls = {e for e, c in calls_by_episode(out).items() if e not in calls_before}
    others = {e for e in new_calls if e.rsplit("-", 1)[0] not in hit["lost_units"]}
    res.check("no other unit made a model call", not others, sorted(others)[:3])
    res.lost += len(after.lost)
    res.duplicated += after.duplicated
    res.check("lost 0, duplicated 0", not after.lost and after.duplicated == 0, (len(after.lost), after.duplicated))
    res.notes.append(
        f"{len(broken)} broken parts + 1 temp file; {len(hit['lost_units'])} terminal rows lost, {len(rerun)} units re-run"
    )
    res.end_run()
    return res
