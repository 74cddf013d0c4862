"""The session removes what episodes left running: before its workers start, for a lost worker,
at its end; a benchmark that cannot remove its leftovers is recorded, not fatal."""

from __future__ import annotations

from typing import Any

from pipeline.leftovers import Leftovers
from pipeline.spec import parse_spec
from workers.envs.registry import Benchmark, registered_benchmark


class Boxes(Benchmark):
    """A benchmark whose environments 'leave' boxes, counted per (run, worker)."""

    name = "boxes"

    def __init__(self, broken: bool = False) -> None:
        self.calls: list[tuple[str, str | None]] = []
        self.broken = broken

    def list_instances(self, selector: str | None = None) -> list[str]:
        return ["boxes/a"]

    def make(self, instance_id: str, **options: Any) -> Any:
        raise NotImplementedError

    def remove_leftovers(self, run_id: str, worker_id: str | None = None) -> int:
        self.calls.append((run_id, worker_id))
        if self.broken:
            raise RuntimeError("daemon gone")
        return 2 if worker_id is None else 1


SPEC = """
run: t
output: {out}
models: [{{model: offline/expert}}]
methods: [{{method: react}}]
environments:
  - {{benchmark: boxes, instances: [boxes/a]}}
  - {{benchmark: robotouille, tasks: [synchronous/2], limit: 1}}
"""


def _spec(tmp_path):
    return parse_spec(SPEC.format(out=tmp_path))


def test_leftovers_are_removed_for_the_run_and_for_one_worker(tmp_path):
    events: list[tuple[str, dict[str, Any]]] = []
    boxes = Boxes()
    with registered_benchmark("boxes", boxes):
        left = Leftovers(_spec(tmp_path), "run1", lambda kind, **detail: events.append((kind, detail)))
        assert left.benchmarks == ["boxes", "robotouille"]
        assert left.remove() == 2
        assert left.remove("w-ab-3") == 1
    assert boxes.calls == [("run1", None), ("run1", "w-ab-3")]
    assert events == [("leftovers_removed", {"removed": 2}), ("leftovers_removed", {"removed": 1, "worker": "w-ab-3"})]


def test_a_benchmark_that_cannot_remove_is_an_event_not_a_failure(tmp_path):
    events: list[tuple[str, dict[str, Any]]] = []
    with registered_benchmark("boxes", Boxes(broken=True)):
        left = Leftovers(_spec(tmp_path), "run1", lambda kind, **detail: events.append((kind, detail)))
        assert left.remove("w-1") == 0
    assert events == [
        ("leftovers_removed", {"severity": "warning", "benchmark": "boxes", "worker": "w-1", "error": "daemon gone"})
    ]
