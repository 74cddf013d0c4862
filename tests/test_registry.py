"""The one registry mechanism (recap.registry.Registry) behind methods and benchmarks: lazy
references, both registration forms, one wording for unknown names, thread safety, and the
built-ins known in a fresh process without any other module imported first."""

from __future__ import annotations

import subprocess
import sys
import threading
from pathlib import Path

import pytest

from recap.config import ConfigError
from recap.method_registry import METHODS
from recap.registry import Registry, import_reference
from workers.envs.registry import BENCHMARKS, EXTRA_FOLDERS

REPO = Path(__file__).resolve().parents[1]


def test_call_form_decorator_form_and_one_unknown_wording():
    reg: Registry[object] = Registry("widget", error=LookupError)
    reg.register("a", 1)

    @reg.register("b")
    def b() -> int:
        return 2

    assert b() == 2  # the decorator returns the object unchanged
    assert reg.names() == ["a", "b"] and list(reg) == ["a", "b"] and len(reg) == 2
    assert reg["a"] == 1 and reg.get("b") is b and reg.items() == [("a", 1), ("b", b)]
    assert "a" in reg and "c" not in reg
    with pytest.raises(LookupError, match=r"^unknown widget 'c'; known: a, b$"):
        reg.get("c")
    with pytest.raises(LookupError, match=r"^widget 'a' is already registered$"):
        reg.register("a", 3)
    reg.unregister("a")
    with pytest.raises(LookupError, match=r"^widget 'a' is not registered$"):
        reg.unregister("a")
    with pytest.raises(LookupError, match=r"^unknown widget 'a'; known: b$"):
        reg["a"]


def test_a_reference_is_imported_on_first_use_and_kept():
    seen: list[object] = []

    def coerce(name: str, obj: object) -> object:
        seen.append(obj)
        return obj

    reg: Registry[object] = Registry("thing", coerce=coerce, attribute="BENCHMARK")
    reg.register("fn", "recap.registry:import_reference")
    reg.register("default", "workers.envs.blocksworld")  # the registry's default attribute
    reg.register("missing", "no_such_package.anywhere")
    assert seen == []  # registering imports nothing
    assert reg["fn"] is import_reference and reg["fn"] is import_reference
    assert seen == [import_reference]  # resolved once
    assert type(reg["default"]).__name__ == "BlocksworldBenchmark"
    with pytest.raises(ModuleNotFoundError):
        reg["missing"]
    assert "missing" in reg  # a broken entry affects that entry only
    assert import_reference("recap.registry") is sys.modules["recap.registry"]  # no attribute: the module


def test_concurrent_registrations_and_lookups_are_consistent():
    reg: Registry[int] = Registry("n", error=ValueError)
    errors: list[str] = []

    def work(i: int) -> None:
        for j in range(200):
            name = f"{i}-{j}"
            reg.register(name, j)
            if reg[name] != j:
                errors.append(name)
            try:
                reg.register(name, j)
            except ValueError:
                pass
            else:
                errors.append(f"twice {name}")

    threads = [threading.Thread(target=work, args=(i,)) for i in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and len(reg) == 1600


def test_methods_and_benchmarks_use_the_one_mechanism():
    assert isinstance(METHODS, Registry) and isinstance(BENCHMARKS, Registry) and isinstance(EXTRA_FOLDERS, Registry)
    assert (METHODS.kind, BENCHMARKS.kind) == ("method", "benchmark")
    with pytest.raises(ConfigError, match=r"^unknown method 'x'; known: recap, react, act, cot, standard, adapt, mini_swe$"):
        METHODS.get("x")


def test_a_method_registers_by_decorator_with_its_own_config_class():
    from recap.baselines import ReActAgent, ReActConfig

    @METHODS.register("deco")
    class Deco(ReActAgent):
        style = "deco"

    try:
        assert METHODS["deco"] == (Deco, ReActConfig)
    finally:
        METHODS.unregister("deco")
    assert "deco" not in METHODS


def test_a_bad_lazy_method_entry_fails_on_use_with_the_registration_wording():
    METHODS.register("wrong", ("recap.baselines:ReActAgent", "recap.baselines:ReActConfig"))
    try:
        with pytest.raises(ConfigError, match=r"^method 'wrong': ReActAgent.style must be 'wrong'$"):
            METHODS["wrong"]
    finally:
        METHODS.unregister("wrong")


FRESH = """
import sys
from recap.blocksworld import BENCHMARK
demo = BENCHMARK.make("blocksworld/3@1").demonstration()
print(list(demo.replies))
print(sorted(m for m in ("recap.methods", "recap.recap_agent", "recap.baselines") if m in sys.modules))
from workers.envs.registry import benchmark_names
print(benchmark_names())
print([m for m in ("workers.envs.blocksworld", "workers.envs.robotouille", "workers.envs.alfworld", "workers.envs.fever", "workers.envs.swe", "workers.envs.swe_verified") if m in sys.modules])
"""


def test_a_fresh_process_knows_every_builtin_without_side_effect_imports():
    """Demonstration replies come from the method registry even when nothing imported
    recap.methods (the agent modules are imported on use); listing the benchmarks imports none."""
    out = subprocess.run([sys.executable, "-c", FRESH], cwd=REPO, capture_output=True, text=True, check=True).stdout
    assert out.splitlines() == [
        "['recap', 'react', 'act', 'cot', 'standard']",
        "['recap.baselines', 'recap.recap_agent']",
        "['blocksworld', 'robotouille', 'alfworld', 'fever', 'swe', 'swe-verified']",
        "[]",
    ]
