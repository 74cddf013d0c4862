"""Files a user hands us (issue 35, items 11 and 12): each attack one line, exit 2, nothing written.

The attacks, each a function of the scenario's :class:`Materials` and an empty case folder that
returns what happened (:class:`Outcome`); ``tests/workers/envs/swe_verified/test_from_file_bounds.py``
and ``tests/workers/envs/swe/test_user_files.py`` assert them one by one, :func:`userfiles` plays
them all for the chaos lab (``python -m tests.pipeline.chaos.lab --only userfiles``):

* ``recap data fetch swebench-verified --from FILE``: a million records whose first is bad, fed
  through a FIFO (refused after a bounded prefix: the writer counts what it got in), 200,000
  brackets on a line, a test list nested as deep inside its JSON string, a 17 MiB line, an id
  with ``..``, a gold patch through ``..``;
* the ``benchmark: swe`` instances file through ``recap run --dry-run``: ids with ``/``/``..``, a
  shell metacharacter or 200 characters, ``repo_path`` ``/``, the home folder or a folder holding
  the run folder, gold and test patches out of the repository (``..``, absolute, ``.git/``, a
  symlink out), a 2 MB and a 100 MB problem statement, deep nesting;
* a model's diff out of the repository, judged by the evaluation: refused unapplied
  (``patch_refused``), no sandbox opened;
* ``recap data images`` with selectors of no selector's form, with no data folder.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import Lab, ScenarioResult

#: a model's (or a gold) patch per way out of the repository
PATCHES = {
    "dotdot": (
        "diff --git a/../outside.py b/../outside.py\nnew file mode 100644\n--- /dev/null\n+++ b/../outside.py\n"
        "@@ -0,0 +1 @@\n+owned = True\n"
    ),
    "absolute": "--- /dev/null\n+++ /tmp/recap-eval-owned.py\n@@ -0,0 +1 @@\n+owned = True\n",
    "git hook": (
        "diff --git a/.git/hooks/post-checkout b/.git/hooks/post-checkout\nnew file mode 100755\n--- /dev/null\n"
        "+++ b/.git/hooks/post-checkout\n@@ -0,0 +1,2 @@\n+#!/bin/sh\n+id > /tmp/recap-eval-owned\n"
    ),
    "symlink out": (
        "diff --git a/etc b/etc\nnew file mode 120000\n--- /dev/null\n+++ b/etc\n@@ -0,0 +1 @@\n+/etc\n"
        "\\ No newline at end of file\n"
    ),
    "quoted dotdot": 'diff --git "a/\\056\\056/x.py" "b/\\056\\056/x.py"\nnew file mode 100644\n',
}
#: a problem statement past the 1 MiB cap, and one past the 16 MiB line cap (the issue's 100 MB)
BIG_PROBLEM = 2_000_000
HUGE_PROBLEM = 100_000_000


@dataclass
class Outcome:
    """What one attack did: the exit status and output lines of ``recap`` (or, for the evaluation,
    0 and the log), whether anything was written where the command writes, and figures."""

    code: int
    err: list[str]
    out: list[str] = field(default_factory=list)
    written: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Materials:
    """The good inputs every attack spoils one thing of: the swe example tasks (git repositories)
    and their SWE-bench Verified records."""

    root: Path
    tasks_file: Path

    def task(self, i: int = 0) -> dict[str, Any]:
        """A fresh copy of a good ``benchmark: swe`` record (its ``repo_path`` made absolute)."""
        rec = json.loads(self.tasks_file.read_text().splitlines()[i])
        rec["repo_path"] = str((self.tasks_file.parent / rec["repo_path"]).resolve())
        return rec

    def verified(self, i: int = 0) -> dict[str, Any]:
        """A fresh copy of a good SWE-bench Verified record."""
        from workers.envs.swe_verified.dataset import FIELDS

        r = self.task(i)
        r.update(hints_text="", created_at="2024-01-01T00:00:00Z", environment_setup_commit=r["base_commit"])
        r["difficulty"] = "<15 min fix"
        return {k: r[k] for k in FIELDS}


def materials(root: Path) -> Materials:
    """The example tasks written under ``root`` (two small git repositories)."""
    from workers.envs.swe.examples import make_fixtures

    fx = make_fixtures(root / "fx", ("offbyone", "format"))
    return Materials(root, fx.tasks_file)


# --------------------------------------------------------------------------------------------
# running recap in-process
# --------------------------------------------------------------------------------------------
@contextlib.contextmanager
def _env(**values: str | None) -> Iterator[None]:
    old = {k: os.environ.get(k) for k in values}
    try:
        for k, v in values.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def run_recap(argv: list[str]) -> tuple[int, list[str], list[str]]:
    """(exit status, stdout lines, stderr lines) of ``recap ARGV`` run in this process; a
    traceback is exit -1 with its one line."""
    from pipeline.cli import main

    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except Exception as exc:  # noqa: BLE001 - a traceback is what an attack must not produce
            return -1, [], [f"TRACEBACK {type(exc).__name__}: {exc}"[:500]]
    return code, out.getvalue().splitlines(), [line for line in err.getvalue().splitlines() if line.strip()]


def _files(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")) if folder.exists() else []


# --------------------------------------------------------------------------------------------
# item 11: recap data fetch swebench-verified --from FILE
# --------------------------------------------------------------------------------------------
def fetch_from(d: Path, source: Path) -> Outcome:
    """``recap data fetch swebench-verified --from SOURCE --subset`` with recap-eval's cache in
    ``d/cache``; ``written``: what the cache holds after."""
    cache = d / "cache"
    with _env(RECAP_EVAL_CACHE=str(cache), SWEBENCH_VERIFIED_DATA=None):
        code, out, err = run_recap(["data", "fetch", "swebench-verified", "--from", str(source), "--subset"])
    return Outcome(code, err, out, _files(cache))


def _jsonl(path: Path, rows: list[Any]) -> Path:
    path.write_text("".join((r if isinstance(r, str) else json.dumps(r)) + "\n" for r in rows), encoding="utf-8")
    return path


def fetch_million_first_bad_fifo(m: Materials, d: Path, records: int = 1_000_000) -> Outcome:
    """A million records, the first missing its fields, fed through a FIFO by a writer that
    counts the bytes the reader took in (``extra``: ``sent``, ``total``): a reader that validates
    while streaming stops after a bounded prefix; one that reads everything first takes it all."""
    d.mkdir(parents=True, exist_ok=True)
    fifo = d / "million.jsonl"
    os.mkfifo(fifo)
    first = b'{"instance_id": "bad"}\n'
    line = json.dumps({**m.verified(), "instance_id": "fixture__offbyone-1"}).encode() + b"\n"
    total = len(first) + len(line) * (records - 1)
    sent = {"bytes": 0}

    def write() -> None:
        try:
            with open(fifo, "wb", buffering=0) as f:  # blocks until the reader opens it
                sent["bytes"] += f.write(first) or 0
                for _ in range(records - 1):
                    sent["bytes"] += f.write(line) or 0  # blocks while the pipe is full
        except OSError:  # BrokenPipeError: the reader is gone
            pass

    writer = threading.Thread(target=write, daemon=True)
    writer.start()
    out = fetch_from(d, fifo)
    if writer.is_alive():  # a reader that never opened the FIFO: let the writer's open return
        with contextlib.suppress(OSError):
            os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))
    writer.join(timeout=60)
    out.extra.update(sent=sent["bytes"], total=total, writer_stuck=writer.is_alive())
    return out


def fetch_deep_line(m: Materials, d: Path, depth: int = 200_000) -> Outcome:
    """A line of ``depth`` nested arrays after a good record."""
    d.mkdir(parents=True, exist_ok=True)
    return fetch_from(d, _jsonl(d / "deep.jsonl", [m.verified(), "[" * depth + "]" * depth]))


def fetch_deep_test_list(m: Materials, d: Path, depth: int = 100_000) -> Outcome:
    """A record whose FAIL_TO_PASS string is ``depth`` nested arrays (json.loads again inside)."""
    d.mkdir(parents=True, exist_ok=True)
    return fetch_from(d, _jsonl(d / "deep.jsonl", [{**m.verified(), "FAIL_TO_PASS": "[" * depth + "]" * depth}]))


def fetch_long_line(m: Materials, d: Path, size: int = 17 << 20) -> Outcome:
    """A valid record of ``size`` bytes (its hints text), past the 16 MiB line cap."""
    d.mkdir(parents=True, exist_ok=True)
    return fetch_from(d, _jsonl(d / "long.jsonl", [{**m.verified(), "hints_text": "x" * size}]))


def fetch_record(m: Materials, d: Path, change: dict[str, Any]) -> Outcome:
    """A good record with ``change`` applied (an id with ``..``, a gold patch out of the repository)."""
    d.mkdir(parents=True, exist_ok=True)
    return fetch_from(d, _jsonl(d / "verified.jsonl", [{**m.verified(), **change}]))


# --------------------------------------------------------------------------------------------
# item 12: the benchmark: swe instances file, a model's patch, recap data images
# --------------------------------------------------------------------------------------------
SWEEP = """run: userfiles
output: {out}
models:
  - model: offline/expert
methods:
  - method: react
environments:
  - benchmark: swe
    tasks: [all]
    options: {{instances_file: "{tasks}", sandbox: docker}}
"""


def swe_dry_run(d: Path, records: list[Any], output: Path | None = None) -> Outcome:
    """``recap run SWEEP --dry-run`` on an instances file of ``records`` (its run folder
    ``d/out`` unless ``output``); ``written``: what the run folder holds after."""
    d.mkdir(parents=True, exist_ok=True)
    tasks = _jsonl(d / "tasks.jsonl", records)
    out = output if output is not None else d / "out"
    spec = d / "sweep.yaml"
    spec.write_text(SWEEP.format(out=out, tasks=tasks), encoding="utf-8")
    code, stdout, err = run_recap(["run", str(spec), "--dry-run", "--progress", "off"])
    return Outcome(code, err, stdout, _files(out) if output is None else [])


def swe_record(m: Materials, d: Path, change: dict[str, Any]) -> Outcome:
    """A good swe record with ``change`` applied."""
    return swe_dry_run(d, [{**m.task(), **change}])


def swe_big_problem(m: Materials, d: Path, size: int) -> Outcome:
    """A problem statement of ``size`` bytes (past 16 MiB: past the line cap too)."""
    return swe_record(m, d, {"problem_statement": "x" * size})


def swe_deep_line(m: Materials, d: Path, depth: int = 200_000) -> Outcome:
    """A record nested ``depth`` levels deep in an extra field."""
    return swe_dry_run(d, [m.task(), '{"extra": ' + "[" * depth + "]" * depth + "}"])


def swe_run_inside_repo(m: Materials, d: Path) -> Outcome:
    """A run folder inside the task's repository (nothing may appear there)."""
    repo = Path(m.task()["repo_path"])
    out = repo / "runs" / d.name
    res = swe_dry_run(d, [m.task()], output=out)
    res.written = _files(out)
    return res


def model_patch(m: Materials, d: Path, patch: str) -> Outcome:
    """A model's diff judged by the evaluation (grading ``ours``) with an opener that counts the
    clean sandboxes asked for: ``extra`` ``reason`` and ``opened``; ``err`` the evaluation's log."""
    from workers.envs.swe.evaluate import evaluate
    from workers.envs.swe.instances import load_instances

    inst = load_instances(m.tasks_file)[0]
    opened: list[int] = []

    def opener() -> Any:
        opened.append(1)
        raise RuntimeError("a clean sandbox was asked for")

    try:
        ev = evaluate(inst, patch, opener, grading="ours")
    except Exception as exc:  # noqa: BLE001 - main's code applies it: the opener raises
        return Outcome(-1, [f"{type(exc).__name__}: {exc}"], extra={"reason": None, "opened": len(opened)})
    return Outcome(0, ev.log.splitlines(), extra={"reason": ev.reason, "success": ev.success, "opened": len(opened)})


def images_selector(m: Materials, d: Path, selector: str) -> Outcome:
    """``recap data images swebench-verified SELECTOR`` with no data folder."""
    cache = d / "cache"
    with _env(RECAP_EVAL_CACHE=str(cache), SWEBENCH_VERIFIED_DATA=None):
        code, out, err = run_recap(["data", "images", "swebench-verified", selector])
    return Outcome(code, err, out, _files(cache))


# --------------------------------------------------------------------------------------------
# the scenario
# --------------------------------------------------------------------------------------------
#: (attack name, run it, a piece of the one line)
Attack = tuple[str, Callable[[Materials, Path], Outcome], str]


def attacks() -> list[Attack]:
    """Every attack of the scenario with the piece of its one line that names the problem."""
    out: list[Attack] = [
        ("fetch: 1,000,000 records, the first bad (FIFO)", fetch_million_first_bad_fifo, "million.jsonl:1: missing field"),
        ("fetch: 200,000 nested arrays on a line", fetch_deep_line, "deep.jsonl:2: nested deeper than 64 levels"),
        ("fetch: a test list nested 100,000 deep", fetch_deep_test_list, "deep.jsonl:1: field 'FAIL_TO_PASS'"),
        ("fetch: a 17 MiB line", fetch_long_line, "long.jsonl:1: longer than 16777216 bytes"),
        (
            "fetch: an instance id with '..'",
            lambda m, d: fetch_record(m, d, {"instance_id": "fixture__off..byone-1", "repo": "fixture/off..byone"}),
            "verified.jsonl:1: instance_id must be letters",
        ),
        (
            "fetch: a gold patch through '..'",
            lambda m, d: fetch_record(m, d, {"patch": PATCHES["dotdot"]}),
            "verified.jsonl:1: field 'patch': line 1 of the patch names 'a/../outside.py'",
        ),
        (
            "swe: instance_id with '/' and '..'",
            lambda m, d: swe_record(m, d, {"instance_id": "x/../../y"}),
            "field 'instance_id'",
        ),
        ("swe: instance_id with ';'", lambda m, d: swe_record(m, d, {"instance_id": "a;id"}), "field 'instance_id'"),
        ("swe: a 200-character instance_id", lambda m, d: swe_record(m, d, {"instance_id": "a" * 200}), "more than 128"),
        ("swe: repo_path /", lambda m, d: swe_record(m, d, {"repo_path": "/"}), "field 'repo_path': / is the root folder"),
        ("swe: repo_path ~", lambda m, d: swe_record(m, d, {"repo_path": "~"}), "is the home folder or above it"),
        ("swe: repo_path holds the run folder", swe_run_inside_repo, "the run folder is inside"),
        ("swe: 2 MB problem_statement", lambda m, d: swe_big_problem(m, d, BIG_PROBLEM), "field 'problem_statement' is"),
        ("swe: 100 MB problem_statement", lambda m, d: swe_big_problem(m, d, HUGE_PROBLEM), "longer than 16777216 bytes"),
        ("swe: 200,000 nested arrays", swe_deep_line, "tasks.jsonl:2: nested deeper than 64 levels"),
        *(
            (f"swe: gold patch {kind}", _gold(kind), "field 'patch': line")
            for kind in ("dotdot", "absolute", "git hook", "symlink out", "quoted dotdot")
        ),
        ("swe: test_patch through '..'", lambda m, d: swe_record(m, d, {"test_patch": PATCHES["dotdot"]}), "field 'test_patch'"),
        *((f"model patch {kind}", _model(kind), "refused before it was applied") for kind in PATCHES),
        *(
            (
                f"images: selector {s!r}" if len(s) < 40 else f"images: a {len(s):,}-character selector",
                _selector(s),
                "is not a selector",
            )
            for s in ("../x", "django__django-1;rm", "", "a/b/c", "x" * 10_000)
        ),
    ]
    return out


def _gold(kind: str) -> Callable[[Materials, Path], Outcome]:
    return lambda m, d: swe_record(m, d, {"patch": PATCHES[kind]})


def _model(kind: str) -> Callable[[Materials, Path], Outcome]:
    return lambda m, d: model_patch(m, d, PATCHES[kind])


def _selector(selector: str) -> Callable[[Materials, Path], Outcome]:
    return lambda m, d: images_selector(m, d, selector)


#: the most of the million-record file a streaming reader may take in before it refuses (its
#: 64 KiB read buffer, the pipe's 64 KiB, a record in the writer's hands)
FIFO_BOUND = 1 << 20


def held(name: str, res: Outcome, expect: str) -> tuple[bool, str]:
    """Whether an attack was refused as the brief says, and the detail for the table."""
    if name.startswith("model patch"):
        ok = res.extra.get("reason") == "patch_refused" and res.extra.get("opened") == 0 and any(expect in x for x in res.err)
        return ok, f"reason {res.extra.get('reason')}, sandboxes opened {res.extra.get('opened')}: {res.err[:1]}"
    ok = res.code == 2 and len(res.err) == 1 and expect in res.err[0] and not res.written
    if "sent" in res.extra:
        ok = ok and res.extra["sent"] < FIFO_BOUND
        return ok, f"exit {res.code}, {res.extra['sent']} of {res.extra['total']} bytes read: {res.err[:1]}"
    return ok, f"exit {res.code}, {len(res.err)} line(s), written {res.written[:3]}: {(res.err or [''])[0][:200]}"


def userfiles(lab: Lab) -> ScenarioResult:
    """Every attack once: one line, exit 2, nothing written (a model's patch: refused unapplied)."""
    cases = attacks()
    res = ScenarioResult(f"user files ({len(cases)} attacks)")
    res.begin_run()
    root = lab.folder("userfiles")
    m = materials(root)
    from workers.envs.swe.instances import load_instances

    (root / "control").mkdir()
    good = load_instances(_jsonl(root / "control" / "tasks.jsonl", [m.task(), m.task(1)]))
    res.check("control: a good instances file loads", len(good) == 2, [i.id for i in good])
    control = fetch_record(m, root / "control-fetch", {})
    res.check("control: a good --from file is stored", control.code == 0 and control.written, control.err[:1])
    ok_count = 0
    for i, (name, attack, expect) in enumerate(cases):
        try:
            out = attack(m, root / f"case-{i:02d}")
            ok, detail = held(name, out, expect)
        except Exception as exc:  # noqa: BLE001 - an attack that crashes the harness did not hold
            ok, detail = False, f"{type(exc).__name__}: {exc}"[:300]
        ok_count += ok
        res.check(name, ok, detail)
    res.notes.append(f"{ok_count}/{len(cases)} held")
    res.end_run()
    return res
