"""Bad input across the sweep file and the command line: one line, non-zero exit, nothing
written, no model call.

Each case starts from a sweep that is valid (checked: ``--dry-run`` accepts it) whose model is
the fake server, changes one thing, and runs ``recap`` in-process. A case passes when the exit
status is non-zero, stderr is exactly one line naming the problem, the fake server saw no
request and the case folder holds exactly the files it held before.
"""

from __future__ import annotations

import contextlib
import io
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tests.pipeline.chaos.harness import KEY_ENV, Lab, ScenarioResult

GOOD = """run: bad-input
output: {out}
models:
  - model: openai/fake-gpt
    api_base: {url}
    api_key_env: RECAP_CHAOS_KEY
methods:
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["3"]
seeds: [0]
workers: 2
"""
MODEL_LINE = "    api_key_env: RECAP_CHAOS_KEY"


@dataclass(frozen=True)
class Case:
    name: str
    #: (case folder, fake server URL) -> argv for ``recap``; may create files first
    argv: Callable[[Path, str], list[str]]
    #: a piece of the one-line message
    expect: str


def good(d: Path, url: str, out: str | None = None) -> str:
    return GOOD.format(out=out.format(d=d) if out else d / "out", url=url)


def _spec(
    change: tuple[str, str] | None = None,
    text: str | bytes | None = None,
    out: str | None = None,
    edit: Callable[[str], str] | None = None,
) -> Callable[[Path, str], list[str]]:
    """``recap run SPEC`` on GOOD with one replacement or edit (or on a given text)."""

    def make(d: Path, url: str) -> list[str]:
        spec = d / "sweep.yaml"
        if text is not None:
            spec.write_bytes(text if isinstance(text, bytes) else text.encode())
        else:
            body = good(d, url, out)
            if change is not None:
                assert change[0] in body, change
                body = body.replace(*change)
            if edit is not None:
                body = edit(body)
            spec.write_text(body)
        return ["run", str(spec), "--progress", "off"]

    return make


def _without_models(text: str) -> str:
    head, rest = text.split("models:\n", 1)
    return head + "models: []\n" + "methods:" + rest.split("methods:", 1)[1]


def _flags(*extra: str) -> Callable[[Path, str], list[str]]:
    def make(d: Path, url: str) -> list[str]:
        return _spec()(d, url)[:2] + list(extra)

    return make


def _run_folder(d: Path, url: str, *, spec_text: tuple[str, str] | None = None, run_json: str | None = None) -> Path:
    """A run folder as a started run leaves it (identity, spec, plan), without Ray."""
    from pipeline.spec import parse_spec
    from pipeline.store import PLAN_FILE, SPEC_FILE, RunStore
    from pipeline.units import expand

    out = d / "out"
    text = good(d, url)
    store = RunStore(out)
    store.create_identity("bad-input")
    store.write_text(SPEC_FILE, text.replace(*spec_text) if spec_text is not None else text)
    store.write_text(PLAN_FILE, expand(parse_spec(text)).to_json() + "\n")
    if run_json is not None:
        (out / "run.json").write_text(run_json)
    return out


def _other_run(d: Path, url: str) -> list[str]:
    from pipeline.store import RunStore

    RunStore(d / "out").create_identity("someone-else")
    return _spec()(d, url)


def _file_as_parent(d: Path, url: str) -> list[str]:
    (d / "a-file").write_text("x")
    return _spec(out="{d}/a-file/run")(d, url)


def _on_folder(*argv: str, **folder: Any) -> Callable[[Path, str], list[str]]:
    def make(d: Path, url: str) -> list[str]:
        out = _run_folder(d, url, **folder)
        return [a.replace("RUN", str(out)).replace("DIR", str(d)) for a in argv]

    return make


CASES = [
    Case("typo in a top-level key", _spec(("workers: 2", "wrokers: 2")), "wrokers: unknown field"),
    Case("typo in a model setting", _spec((MODEL_LINE, MODEL_LINE + "\n    rmp: 100")), "models[0].rmp: unknown field"),
    Case("no models", _spec(edit=_without_models), "models: List should have at least 1 item"),
    Case("zero workers", _spec(("workers: 2", "workers: 0")), "workers: 0 is out of range [1, 1024]"),
    Case("repeated seed", _spec(("seeds: [0]", "seeds: [0, 0]")), "seeds: repeated seed"),
    Case("run name with a slash", _spec(("run: bad-input", "run: bad input/1")), "run: must be letters, digits"),
    Case(
        "negative step multiplier",
        _spec(("seeds: [0]", "seeds: [0]\nstep_multiplier: -1")),
        "step_multiplier: -1 is out of range [0.1, 1000]",
    ),
    Case(
        "two models with one name",
        _spec(("models:\n", "models:\n  - model: offline/expert\n  - model: offline/expert\n")),
        "models: two entries are both named 'offline/expert'",
    ),
    Case("environment without tasks", _spec(('    tasks: ["3"]', "    limit: 2")), "environments[0]: give 'tasks'"),
    Case("sweep file is a list", _spec(text="- run: x\n"), "the sweep file must be a YAML mapping"),
    Case("empty sweep file", _spec(text=""), "the sweep file must be a YAML mapping"),
    Case("binary sweep file", _spec(text=b"\x89PNG\r\n\x1a\n\xff\xfe\x00"), "cannot be read"),
    Case("unknown profile", _spec(("  - method: react", "  - method: recap\n    profile: papr")), "methods[0]"),
    Case("unknown ablation", _spec(("  - method: react", "  - method: recap\n    ablation: no_thinking")), "no_thinking"),
    Case(
        "test-double options on a real model",
        _spec((MODEL_LINE, MODEL_LINE + "\n    options: {seed: 1}")),
        "'options' are for offline/ test doubles only",
    ),
    Case("negative dollar cap", _spec((MODEL_LINE, MODEL_LINE + "\n    cap_usd: -1")), "models[0].cap_usd"),
    Case("zero rpm", _spec((MODEL_LINE, MODEL_LINE + "\n    rpm: 0")), "models[0].rpm: 0 is out of range [1, 10000000]"),
    Case("zero call limit", _spec(("seeds: [0]", "seeds: [0]\nlimits: {llm_calls: 0}")), "limits.llm_calls"),
    Case(
        "api_base that is not a URL",
        _spec(("api_base: http://", "api_base: localhost:8000 #")),
        "api_base: must be an http(s) URL",
    ),
    Case(
        "temperature that is not a number",
        _spec((MODEL_LINE, MODEL_LINE + "\n    params: {temperature: hot}")),
        "params: temperature must be a number",
    ),
    Case(
        "negative max_tokens",
        _spec((MODEL_LINE, MODEL_LINE + "\n    params: {max_tokens: -5}")),
        "params: max_tokens -5 is out of range [1, 262144]",
    ),
    Case(
        "API key variable not set",
        _spec(("api_key_env: RECAP_CHAOS_KEY", "api_key_env: RECAP_CHAOS_UNSET_KEY")),
        "API key variable RECAP_CHAOS_UNSET_KEY is not set",
    ),
    Case("unknown task", _spec(('tasks: ["3"]', 'tasks: ["99"]')), "no blocksworld instance matches '99'"),
    Case("output under a file", _file_as_parent, "cannot be created"),
    Case("output folder of another run", _other_run, "holds run 'someone-else'"),
    Case("--workers not a number", _flags("--workers", "many"), "argument --workers: invalid int value"),
    Case("--run-cap negative", _flags("--run-cap", "-1"), "run_cap_usd: -1 is out of range [0, 1000000]"),
    Case("missing sweep argument", lambda d, url: ["run"], "the following arguments are required: spec"),
    Case("unknown flag", _flags("--fast"), "unrecognized arguments: --fast"),
    Case("sweep file does not exist", lambda d, url: ["run", str(d / "nope.yaml")], "does not exist"),
    Case("resume: corrupt run.json", _on_folder("resume", "RUN", run_json="{not json"), "is not a valid run file"),
    Case(
        "resume: spec.yaml edited into nonsense",
        _on_folder("resume", "RUN", spec_text=("workers: 2", "workers: -3")),
        "workers: -3 is out of range [1, 1024]",
    ),
    Case(
        "status of a file", lambda d, url: (d / "f.txt").write_text("x") and ["status", str(d / "f.txt")], "is not a run folder"
    ),
    Case("show an unknown episode", _on_folder("show", "RUN", "no-such-episode"), "no episode 'no-such-episode'"),
    Case("sql that would write a file", _on_folder("sql", "RUN", "COPY (SELECT 1) TO 'DIR/leak.csv'"), "rror"),
    Case("report in an unknown format", _on_folder("report", "RUN", "--format", "pdf"), "unknown report format(s) pdf"),
    # spec hardening: bounded values, YAML bombs, duplicate keys, labels, addresses, stores
    Case("seed beyond int64", _spec(("seeds: [0]", "seeds: [9223372036854775808]")), "seeds[0]: integer out of range"),
    Case("boolean worker count", _spec(("workers: 2", "workers: true")), "workers: must be a number, not true/false"),
    Case(
        "nan temperature",
        _spec((MODEL_LINE, MODEL_LINE + "\n    params: {temperature: .nan}")),
        "models[0].params.temperature: must be a finite number",
    ),
    Case(
        "infinite model cap",
        _spec((MODEL_LINE, MODEL_LINE + "\n    cap_usd: .inf")),
        "models[0].cap_usd: must be a finite number",
    ),
    Case(
        "overflowing price",
        _spec((MODEL_LINE, MODEL_LINE + "\n    prices: {input: 1, output: 1e999}")),
        "models[0].prices.output",
    ),
    Case(
        "duplicate cap_usd",
        _spec((MODEL_LINE, MODEL_LINE + "\n    cap_usd: 1\n    cap_usd: 500")),
        "duplicate key 'cap_usd' at line 8",
    ),
    Case(
        "alias bomb",
        _spec(("seeds: [0]", "seeds: [0]\nx0: &a [1, 1, 1, 1, 1, 1, 1, 1, 1]\nx1: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]")),
        "YAML anchors are not allowed",
    ),
    Case("markup in a label", _spec((MODEL_LINE, MODEL_LINE + "\n    label: '[bold]x[/]'")), "models[0].label: may hold only"),
    Case(
        "escape code in a label", _spec((MODEL_LINE, MODEL_LINE + '\n    label: "a\\e[31mb"')), "models[0].label: may hold only"
    ),
    Case("50 kB label", _spec((MODEL_LINE, MODEL_LINE + "\n    label: " + "x" * 50_000)), "at most 4096"),
    Case("sweep file is /dev/zero", lambda d, url: ["run", "/dev/zero"], "not a regular file"),
    Case("2 MB sweep file", _spec(text="# " + "x" * 2_000_000 + "\n"), "at most 1 MiB"),
    Case(
        "unreachable object store",
        _spec(out="s3://bucket/runs/x?endpoint_override=127.0.0.1:1&scheme=http"),
        "cannot connect to 127.0.0.1:1",
    ),
    Case("unknown output scheme", _spec(out="ftp://host/runs/x"), "unknown URI scheme 'ftp'"),
    Case("ray address without a port", _spec(("workers: 2", "workers: 2\nray: {address: head-node}")), "ray.address: must be"),
    Case("--address out of range", _flags("--address", "10.0.0.5:99999"), "ray.address: must be"),
    Case("--run-cap nan", _flags("--run-cap", "nan"), "run_cap_usd: Input should be a finite number"),
]


def _snapshot(d: Path) -> dict[str, tuple[int, int]]:
    return {str(p.relative_to(d)): (p.stat().st_size, p.stat().st_mtime_ns) for p in d.rglob("*") if p.is_file()}


def run_case(case: Case, d: Path, server: object) -> tuple[int, list[str], list[str]]:
    """(exit status, stderr lines, problems) of one case."""
    from pipeline.cli import main

    d.mkdir(parents=True, exist_ok=True)
    argv = case.argv(d, server.base_url)  # type: ignore[attr-defined]
    before = _snapshot(d)
    arrivals = len(server.log)  # type: ignore[attr-defined]
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code = main(argv)
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else 1
        except Exception as exc:  # noqa: BLE001 - a traceback is what the case must not produce
            code, err = -1, io.StringIO(f"TRACEBACK {type(exc).__name__}: {exc}\n")
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    problems = []
    if code in (0, -1):
        problems.append(f"exit status {code}")
    if len(lines) != 1:
        problems.append(f"{len(lines)} stderr lines")
    elif case.expect not in lines[0]:
        problems.append(f"message lacks {case.expect!r}")
    if len(server.log) != arrivals:  # type: ignore[attr-defined]
        problems.append("a model call was made")
    if _snapshot(d) != before:
        problems.append("files were written")
    return code, lines, problems


def bad_inputs(lab: Lab, cases: list[Case] | None = None) -> ScenarioResult:
    cases = cases if cases is not None else CASES
    res = ScenarioResult(f"bad inputs ({len(cases)} cases)")
    res.begin_run()
    os.environ[KEY_ENV] = os.environ.get(KEY_ENV) or "sk-chaos-not-used"
    os.environ.pop("RECAP_CHAOS_UNSET_KEY", None)
    server = lab.server()
    root = lab.folder("bad-inputs")
    code, lines, _ = run_case(Case("the valid sweep", _flags("--dry-run"), ""), root / "valid", server)
    res.check("the unchanged sweep is accepted (--dry-run)", code == 0 and not lines, (code, lines))
    failed = 0
    for i, case in enumerate(cases):
        code, lines, problems = run_case(case, root / f"case-{i:02d}", server)
        failed += bool(problems)
        res.check(
            case.name,
            not problems,
            f"exit {code}: {lines[0] if lines else ''}" + (f" ({'; '.join(problems)})" if problems else ""),
        )
    res.notes.append(f"{len(cases) - failed}/{len(cases)} rejected in one line with no write and no model call")
    res.end_run()
    return res
