"""A new benchmark is a package of its own plus one registration: proved with a toy one.

The corridor below (rooms 0..N in a row; ``walk forward`` / ``walk back``; the goal is the last
room) is defined in this file only. It is registered with
:func:`workers.envs.registry.register_benchmark` and played through the episode worker
(:meth:`workers.episode_worker.EpisodeRunner.run_unit`) by an existing method (ReAct) against
the offline expert model, which follows the environment's ``expert_plan()``. Nothing in the
repository names it, and running it writes nothing into the repository.

A real new benchmark ``<name>`` touches (the last test proves it with a package written into a
temporary folder and registered by one line):

* ``workers/envs/<name>/`` - its own package: the :class:`recap.env.Environment` (reset, step,
  rules, demonstration, expert_plan for the offline expert), a ``benchmark.py`` with a
  :class:`workers.envs.registry.Benchmark` subclass exposed as ``BENCHMARK`` (``list_instances``,
  ``make``, and only the hooks it needs: ``declared_options`` for the options a sweep may give
  it, each changing what an episode does (in the unit id) or how it is run (not), any other
  refused (:mod:`workers.envs.options`; declaring nothing, it takes none); ``options_for_agent``
  for per-method ``make()`` options; ``data_folders`` when it reads a data folder, so ``recap data list/check/fetch`` and
  the Ray workers' environment follow; ``canonical_id`` when two spellings of an id name one
  instance; ``place`` when a row's split/task follow from the id where the environment did not
  report them; ``profile_settings`` / ``release_prompt_settings``
  (:class:`recap.config.BenchmarkProtocol`) when a method's ``paper``/``released`` profile
  means something else there - a ``protocol.py`` as Robotouille's and ALFWorld's), and its
  demonstration and rules texts;
* ``workers/envs/registry.py`` - one ``register_benchmark("<name>", "workers.envs.<name>")``
  line in the table of built-ins (Ray workers import the registry, not the test's
  registration);
* ``tests/<name>/`` - its tests;
* only if it has downloadable data: its sha256 manifest ``pipeline/manifests/<folder>.sha256``
  (``recap data check``/``fetch`` verify against it).

No method, config, schema or pipeline module changes: recap learns what a benchmark means only
from what it declares, and a row's split/task are what its environment reports or its
``place`` hook says. Outside its folder only knowledge about *other* things stays per
benchmark: the authors' released prompt files (``workers/release/texts.py``, for a benchmark
they released prompts for), the paper's published numbers (``reports/paper.py``) and the
reading of schema version 1 rows (``schemas/versions.py`` and ``schemas.labels.place_of``,
frozen with that version: schemas cannot ask the benchmarks, and a new benchmark never wrote a
version 1 row; tests/pipeline/spec/test_spec_units.py checks the built-ins' ``place`` hooks agree).
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import pytest

from recap.env import Demonstration, Environment, InvalidActionError, Reset, Step
from schemas.outcomes import EnvFacts, EpisodeResult, UnitWork
from workers.envs import registry
from workers.envs.registry import Benchmark, UnknownInstanceError, register_benchmark, unregister_benchmark

REPO = Path(__file__).resolve().parents[1]
NAME = "corridor"


class Corridor(Environment):
    """Rooms 0..length in a row; the agent starts in room 0 and must reach the last room."""

    benchmark = NAME
    split = "straight"

    def __init__(self, length: int, step_multiplier: float) -> None:
        self.length = length
        self.instance_id = f"{NAME}/{length}"
        self.task = f"length {length}"
        self.optimal_steps = length
        self.max_steps = math.ceil(length * step_multiplier)
        self.room = 0
        self._steps_taken = 0

    def _valid(self) -> tuple[str, ...]:
        return ("walk forward", "walk back") if self.room > 0 else ("walk forward",)

    def _observation(self) -> str:
        return f"You are in room {self.room} of rooms 0 to {self.length}."

    def reset(self) -> Reset:
        self.room, self._steps_taken = 0, 0
        return Reset(self._observation(), self._valid(), f"reach room {self.length}")

    def step(self, action: str) -> Step:
        if action not in self._valid():
            raise InvalidActionError(action)
        self.room += 1 if action == "walk forward" else -1
        self._steps_taken += 1
        done = self.room == self.length
        return Step(self._observation(), self._valid(), done, done)

    def rules(self) -> str:
        return "Rooms are in a row. 'walk forward' enters the next room; 'walk back' returns to the previous one."

    def demonstration(self) -> Demonstration | None:
        return None

    def expert_plan(self) -> list[str]:
        return ["walk forward"] * (self.length - self.room)


class CorridorBenchmark(Benchmark):
    name = NAME

    def list_instances(self, selector: str | None = None) -> list[str]:
        return [f"{NAME}/{n}" for n in (2, 3)]

    def make(self, instance_id: str, *, step_multiplier: float = 4.0, **options: object) -> Environment:
        if instance_id not in self.list_instances() or options:
            raise UnknownInstanceError(f"unknown corridor {instance_id!r} or options {sorted(options)}")
        return Corridor(int(instance_id.split("/")[1]), step_multiplier)


class ExpertFactory:
    """The worker's client factory, in-process: every model label is the offline expert."""

    writes_llm_calls = False

    def client(self, model: str):
        from workers.llm.direct import LiteLLMClient
        from workers.llm.providers import DeploymentConfig

        return LiteLLMClient(DeploymentConfig(model="offline/expert"))


@pytest.fixture
def corridor():
    register_benchmark(NAME, CorridorBenchmark)  # a factory: built on first use
    try:
        yield
    finally:
        unregister_benchmark(NAME)


def _git_status() -> str | None:
    try:
        done = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=all"], cwd=REPO, capture_output=True, text=True, timeout=60
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout if done.returncode == 0 else None


TASK_PROMPT = (
    "You are an agent that reaches a goal in an environment one action at a time. At every turn you think "
    "about the latest observation, then choose exactly one action; I carry it out and show you what happened. "
    "An action that is not one of the valid actions is not carried out, and I tell you so.\n\n"
    "Answer every time with one JSON object and nothing else:\n"
    '{"think": "<your reasoning>", "action": "<one valid action>"}\n'
    '- "think": your reasoning before acting: what the goal still needs, what the latest observation and your '
    "earlier steps tell you, and why the action you choose moves you towards the goal. If your last action was "
    "rejected, first work out why it was not valid.\n"
    '- "action": the single next action, written exactly as it appears among the valid actions.\n\n'
    "Rules of the environment:\n"
    "Rooms are in a row. 'walk forward' enters the next room; 'walk back' returns to the previous one.\n\n"
    "Initial observation:\nYou are in room 0 of rooms 0 to 3.\n\n"
    "Your goal:\nreach room 3\n\n"
    "Reply with your first action."
)


def test_a_benchmark_defined_in_a_test_plays_an_episode_through_the_worker(corridor):
    from recap.methods import make_agent
    from workers.episode_worker import EpisodeRunner

    before = _git_status()
    config = make_agent("react", benchmark=registry.get_benchmark(NAME)).config.to_json()
    unit = UnitWork("u1", f"{NAME}/3", "react", config, "expert", "offline/expert", sampling_seed=0, step_multiplier=2.0)
    batches: list[dict[str, list[dict]]] = []
    runner = EpisodeRunner("w1", "run1", ExpertFactory(), send=batches.append, wait=lambda ref: None)

    out = runner.run_unit(unit, 1)

    assert out.crash is None
    assert out.env == EnvFacts(benchmark=NAME, split="straight", task="length 3", optimal_steps=3, max_steps=6)
    assert (out.episode_id, out.model, out.test_double) == ("u1-1", "offline/expert", True)
    result = out.result
    assert isinstance(result, EpisodeResult)
    assert (
        result.end_reason,
        result.success,
        result.steps,
        result.llm_calls,
        result.invalid_actions,
        result.json_repairs,
        result.error,
    ) == ("success", True, 3, 3, 0, 0, None)

    rows: dict[str, list[dict]] = {}
    for batch in batches:
        for table, part in batch.items():
            rows.setdefault(table, []).extend(part)
    assert out.rows_sent == sum(len(v) for v in rows.values()) == 6 + 3 + 3
    messages = [(m["seq"], m["role"], m["kind"], m["content"], m["pinned"]) for m in rows["messages"]]
    assert messages == [
        (0, "user", "task", TASK_PROMPT, True),
        (1, "assistant", "reply", '{"think": "Expert plan: 3 action(s) left.", "action": "walk forward"}', False),
        (2, "user", "observation", "Observation:\nYou are in room 1 of rooms 0 to 3.", False),
        (3, "assistant", "reply", '{"think": "Expert plan: 2 action(s) left.", "action": "walk forward"}', False),
        (4, "user", "observation", "Observation:\nYou are in room 2 of rooms 0 to 3.", False),
        (5, "assistant", "reply", '{"think": "Expert plan: 1 action(s) left.", "action": "walk forward"}', False),
    ]
    steps = [
        (s["index"], s["env_step"], s["action"], s["valid"], s["observation"], s["done"], s["success"]) for s in rows["steps"]
    ]
    assert steps == [
        (0, 1, "walk forward", True, "You are in room 1 of rooms 0 to 3.", False, False),
        (1, 2, "walk forward", True, "You are in room 2 of rooms 0 to 3.", False, False),
        (2, 3, "walk forward", True, "You are in room 3 of rooms 0 to 3.", True, True),
    ]
    calls = [
        (c["call_index"], c["purpose"], c["window_seqs"], c["response_seq"], c["status"], c["model"]) for c in rows["llm_calls"]
    ]
    assert calls == [
        (0, "task", [0], 1, "ok", "offline/expert"),
        (1, "observation", [0, 1, 2], 3, "ok", "offline/expert"),
        (2, "observation", [0, 1, 2, 3, 4], 5, "ok", "offline/expert"),
    ]

    # no repository file names the corridor, and playing it wrote nothing into the checkout
    sources = [p for pkg in ("recap", "workers", "pipeline", "schemas", "reports") for p in (REPO / pkg).rglob("*.py")]
    assert [str(p) for p in sources if NAME in p.read_text()] == []
    assert _git_status() == before


def test_registration_is_lazy_named_once_and_undone(corridor):
    built: list[str] = []

    def factory() -> Benchmark:
        built.append("tunnel")
        bench = CorridorBenchmark()
        bench.name = "tunnel"
        return bench

    assert registry.benchmark_names() == ["blocksworld", "robotouille", "alfworld", "fever", "swe", "swe-verified", NAME]
    register_benchmark("tunnel", factory)
    try:
        assert built == []
        assert registry.get_benchmark("tunnel") is registry.get_benchmark("tunnel") and built == ["tunnel"]
        with pytest.raises(ValueError, match="^benchmark 'tunnel' is already registered$"):
            register_benchmark("tunnel", CorridorBenchmark)
    finally:
        unregister_benchmark("tunnel")
    with pytest.raises(
        UnknownInstanceError,
        match=r"^unknown benchmark 'tunnel'; known: blocksworld, robotouille, alfworld, fever, swe, swe-verified, corridor$",
    ):
        registry.get_benchmark("tunnel")
    # the declared hooks' defaults: no per-method options, no data folder, nothing to forward
    bench = registry.get_benchmark(NAME)
    assert (bench.options_for_agent("react"), dict(bench.data_folders()), bench.data_env_vars()) == ({}, {}, ())
    assert registry.make_env(f"{NAME}/2", step_multiplier=1.5).max_steps == 3


def test_a_benchmark_that_cannot_be_imported_affects_only_itself():
    register_benchmark("ghost", "tests.no_such_benchmark_module")
    try:
        with pytest.raises(ModuleNotFoundError):
            registry.get_benchmark("ghost")
        # the authors' released prompts (registered on their own, not a benchmark's) come last
        assert registry.data_env_vars() == (
            "ROBOTOUILLE_DATA",
            "ALFWORLD_DATA",
            "ALFWORLD_DATA_2_1_2",
            "FEVER_DATA",
            "SWEBENCH_VERIFIED_DATA",
            "RECAP_RELEASE_DATA",
        )
        assert list(registry.data_folders()) == [
            "robotouille",
            "alfworld",
            "alfworld-2.1.2",
            "fever",
            "swebench-verified",
            "recap-release",
        ]
        assert registry.data_folder("alfworld-2.1.2").location.env_var == "ALFWORLD_DATA_2_1_2"
        assert registry.make_env("blocksworld/3@1").instance_id == "blocksworld/3@1"
    finally:
        unregister_benchmark("ghost")
    register_benchmark("plain", lambda: object())  # type: ignore[arg-type,return-value]
    try:
        with pytest.raises(
            TypeError,
            match=r"^benchmark 'plain' resolved to <object object at .*>, which is not a "
            r"workers.envs.registry.Benchmark$",
        ):
            registry.get_benchmark("plain")
    finally:
        unregister_benchmark("plain")
    assert registry.benchmark_names() == ["blocksworld", "robotouille", "alfworld", "fever", "swe", "swe-verified"]


#: a benchmark package of its own, written into a temporary folder: its environment, its
#: Benchmark, and its protocol (what ``paper`` means for ReAct there: a 16-message window)
TOY_PACKAGE = """
from recap.baselines.react import ReActConfig
from recap.env import Environment, InvalidActionError, Reset, Step
from workers.envs.registry import Benchmark


class Ladder(Environment):
    benchmark = "ladder"
    split = "rungs"

    def __init__(self, n, step_multiplier=4.0):
        self.instance_id, self.task, self.optimal_steps = f"ladder/{n}", f"{n} rungs", n
        self.max_steps, self.n, self.at = int(n * step_multiplier), n, 0

    def reset(self):
        self.at = 0
        return Reset("You stand at rung 0.", ("climb",), f"reach rung {self.n}")

    def step(self, action):
        if action != "climb":
            raise InvalidActionError(action)
        self.at += 1
        done = self.at == self.n
        return Step(f"You stand at rung {self.at}.", ("climb",), done, done)

    def rules(self):
        return "'climb' goes up one rung."

    def demonstration(self):
        return None

    def expert_plan(self):
        return ["climb"] * (self.n - self.at)


class LadderBenchmark(Benchmark):
    name = "ladder"

    def list_instances(self, selector=None):
        return ["ladder/2", "ladder/4"]

    def make(self, instance_id, step_multiplier=4.0, **options):
        return Ladder(int(instance_id.split("/")[1]), step_multiplier)

    def profile_settings(self, config_cls, profile, ablation, generic):
        if profile == "paper" and issubclass(config_cls, ReActConfig):
            return {**generic, "window": 16}
        return generic


BENCHMARK = LadderBenchmark()
"""


@pytest.fixture
def ladder(tmp_path, monkeypatch):
    (tmp_path / "ladder_bench").mkdir()
    (tmp_path / "ladder_bench" / "__init__.py").write_text(TOY_PACKAGE)
    monkeypatch.syspath_prepend(str(tmp_path))
    register_benchmark("ladder", "ladder_bench")  # the one registration line, as the built-ins'
    try:
        yield
    finally:
        unregister_benchmark("ladder")


def test_a_benchmark_package_with_one_registration_line_runs_a_unit_under_its_own_protocol(ladder):
    """List, make, resolve a method's profile as the benchmark declares it, play a unit with
    the offline expert through the worker, and get the outcome row's facts: nothing in recap/,
    workers/, pipeline/ or schemas/ changed for it."""
    from workers.episode_worker import EpisodeRunner, build_agent

    assert registry.benchmark_names()[-1] == "ladder"
    assert registry.get_benchmark("ladder").list_instances() == ["ladder/2", "ladder/4"]
    assert registry.make_env("ladder/4", step_multiplier=1.5).max_steps == 6
    # the benchmark's declaration reaches the config by its name; other benchmarks keep theirs
    assert build_agent("react", profile="paper", benchmark="ladder").config.window == 16
    assert build_agent("react", profile="paper", benchmark="blocksworld").config.window == 128
    assert build_agent("react", profile="paper", benchmark="robotouille").config.window == 64
    assert build_agent("cot", profile="paper", benchmark="ladder").config.window == 128

    config = build_agent("react", profile="paper", benchmark="ladder").config.to_json()
    unit = UnitWork("u1", "ladder/4", "react", config, "expert", "offline/expert", sampling_seed=0, step_multiplier=2.0)
    batches: list[dict[str, list[dict]]] = []
    out = EpisodeRunner("w1", "run1", ExpertFactory(), send=batches.append, wait=lambda ref: None).run_unit(unit, 1)

    assert out.crash is None
    assert out.env == EnvFacts(benchmark="ladder", split="rungs", task="4 rungs", optimal_steps=4, max_steps=8)
    result = out.result
    assert isinstance(result, EpisodeResult)
    assert (result.end_reason, result.success, result.steps, result.llm_calls, result.invalid_actions) == (
        "success",
        True,
        4,
        4,
        0,
    )
    steps = [s["action"] for batch in batches for s in batch.get("steps", [])]
    assert steps == ["climb"] * 4


def test_build_agent_refuses_an_unknown_benchmark_by_name():
    from recap.config import ConfigError
    from workers.episode_worker import build_agent

    with pytest.raises(
        ConfigError, match=r"^unknown benchmark 'nowhere'; known: blocksworld, robotouille, alfworld, fever, swe, swe-verified$"
    ):
        build_agent("react", profile="paper", benchmark="nowhere")
