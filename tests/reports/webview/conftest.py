"""Two small real runs (``recap run``'s driver, the offline test doubles, blocksworld) written once
per test session, and a viewer over them.

Run A: offline/expert with a call cap of 12 (ReCAP needs more calls on some instances and ends
``call_cap``); run B: offline/random under the same model label, so the two runs pair unit by
unit and disagree. About 25 s with Ray's start."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq
import pytest

SWEEP = """run: view-{name}
output: {out}
models:
  - model: {model}
    label: expert
    options: {{seed: 3}}
methods:
  - method: recap
  - method: react
environments:
  - benchmark: blocksworld
    tasks: ["3", "4"]
    limit: 2
seeds: [0]
limits: {{llm_calls: 12}}
workers: 2
"""


@pytest.fixture(scope="session")
def real_runs(ray_address: str, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec

    base = tmp_path_factory.mktemp("view_runs")
    out = []
    for name, model in (("a", "offline/expert"), ("b", "offline/random")):  # on the session's Ray
        folder = base / name
        text = SWEEP.format(name=name, out=folder, model=model)
        spec = parse_spec(text, "sweep.yaml")
        summary = Driver(prepare(spec, text), make_backend(spec), progress="off").run()
        assert summary.exit_code() == 0
        out.append(folder)
    return out[0], out[1]


def table(run_dirs, name: str) -> list[dict]:
    """Every row of a table, read straight from the part files (independent of the viewer)."""
    rows: list[dict] = []
    for d in run_dirs:
        for f in sorted((Path(d) / name).glob("part-*.parquet")):
            rows.extend(pq.read_table(f).to_pylist())
    return rows


LONG_SWEEP = """run: view-long
output: {out}
models:
  - model: offline/expert
    label: expert
    options: {{seed: 3}}
methods:
  - method: recap
environments:
  - benchmark: robotouille
    tasks: [asynchronous/9]
    limit: 1
seeds: [0]
workers: 1
"""


@pytest.fixture(scope="session")
def long_run(ray_address: str, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One ReCAP episode of about 100 calls (issue 36 item 9's page): offline/expert on Robotouille's longest
    asynchronous task, written by ``recap run``'s driver like the runs above (a few seconds more)."""
    from pipeline.driver import Driver, prepare
    from pipeline.gateway_backend import make_backend
    from pipeline.spec import parse_spec

    folder = tmp_path_factory.mktemp("view_long") / "long"
    text = LONG_SWEEP.format(out=folder)
    spec = parse_spec(text, "sweep.yaml")
    assert Driver(prepare(spec, text), make_backend(spec), progress="off").run().exit_code() == 0
    return folder
