"""A method entry's own step cap (issue 25 item 4): ``step_multiplier`` and a per-task
``step_multipliers`` map, resolved per unit at planning, in the unit's hash and its rows; every
examples/paper sweep runs each method at the released configs' multiplier on each task.
Refusals go through the real CLI (exit 2, one line, nothing written)."""

from __future__ import annotations

from pathlib import Path

import pytest

from pipeline.cli import main
from pipeline.spec import load_spec, parse_spec
from pipeline.units import expand, unit_hash
from reports import paper
from schemas.labels import place_of

REPO = Path(__file__).resolve().parents[2]

BASE = """run: multipliers
output: {out}
models:
  - model: offline/expert
methods:
  - method: react
    label: react
  - method: act
    label: act
    step_multiplier: 2
  - method: recap
    label: recap
    step_multipliers: {robotouille/synchronous/2: 3, blocksworld/4: 1.5}
environments:
  - benchmark: robotouille
    tasks: [synchronous/2, synchronous/3]
    limit: 1
  - benchmark: blocksworld
    tasks: ["3", "4"]
    limit: 1
seeds: [0]
step_multiplier: 4
"""


def _plan(text: str = BASE):
    return expand(parse_spec(text.replace("{out}", "/tmp/never-written"), "sweep.yaml"))


def test_each_unit_gets_its_methods_multiplier_per_task():
    plan = _plan()
    got = {(u.method_label, u.instance_id.rsplit("@", 1)[0]): u.step_multiplier for u in plan.units}
    assert got == {
        ("react", "robotouille/synchronous/2_lettuce_tomato_sandwich"): 4.0,
        ("react", "robotouille/synchronous/3_burger"): 4.0,
        ("react", "blocksworld/3"): 4.0,
        ("react", "blocksworld/4"): 4.0,
        ("act", "robotouille/synchronous/2_lettuce_tomato_sandwich"): 2.0,
        ("act", "robotouille/synchronous/3_burger"): 2.0,
        ("act", "blocksworld/3"): 2.0,
        ("act", "blocksworld/4"): 2.0,
        ("recap", "robotouille/synchronous/2_lettuce_tomato_sandwich"): 3.0,
        ("recap", "robotouille/synchronous/3_burger"): 4.0,
        ("recap", "blocksworld/3"): 4.0,
        ("recap", "blocksworld/4"): 1.5,
    }
    # the multiplier used is in the unit's hash and in the work a worker plays (its episode rows
    # record it beside the step cap: tests/reports/test_paper_section.py)
    for u in plan.units:
        assert u.unit_id == unit_hash(
            instance_id=u.instance_id,
            method=u.method,
            method_config=u.method_config,
            model=u.model,
            params=u.model_params,
            sampling_seed=u.sampling_seed,
            step_multiplier=u.step_multiplier,
        )
        assert u.work().step_multiplier == u.step_multiplier  # what the worker makes and records
    # the method entry's value is what changes the hash: the same unit at the sweep's x4 differs
    x4 = _plan(BASE.replace("    step_multiplier: 2\n", ""))
    act = {u.instance_id: u.unit_id for u in plan.units if u.method_label == "act"}
    act4 = {u.instance_id: u.unit_id for u in x4.units if u.method_label == "act"}
    assert act.keys() == act4.keys() and all(act[i] != act4[i] for i in act)
    react = {u.instance_id: u.unit_id for u in plan.units if u.method_label == "react"}
    assert react == {u.instance_id: u.unit_id for u in x4.units if u.method_label == "react"}


def _refused(tmp_path: Path, capsys, text: str) -> str:
    out = tmp_path / "out"
    spec = tmp_path / "sweep.yaml"
    spec.write_text(text.replace("{out}", str(out)))
    capsys.readouterr()
    code = main(["run", str(spec), "--dry-run"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, (code, err)
    assert not out.exists()
    return err[0]


E = "recap: error: sweep.yaml: "
TASKS = (
    "0_cheese_sandwich, 1_lettuce_sandwich, 2_lettuce_tomato_sandwich, 3_burger, 4_cheeseburger, 5_double_cheeseburger, "
    "6_lettuce_tomato_cheeseburger, 7_two_lettuce_chicken_sandwich, 8_two_lettuce_tomato_burger, "
    "9_onion_cheese_burger_and_lettuce_tomato_chicken_sandwich"
)


@pytest.mark.parametrize(
    "old, new, message",
    [
        (
            "{robotouille/synchronous/2: 3,",
            "{synchronous/2: 3,",
            E + "methods[2] (recap): step_multipliers: 'synchronous/2': unknown benchmark 'synchronous'; "
            "known: blocksworld, robotouille, alfworld, fever, swe, swe-verified",
        ),
        (
            "{robotouille/synchronous/2: 3,",
            "{robotouille: 3,",
            E
            + "methods[2].step_multipliers: key 'robotouille' must be <benchmark>/<task selector>, e.g. robotouille/synchronous/2",
        ),
        (
            "{robotouille/synchronous/2: 3,",
            "{robotouille/synchronous/12: 3,",
            E + "methods[2] (recap): step_multipliers: 'robotouille/synchronous/12': unknown Robotouille task "
            f"synchronous/'12' in selector 'synchronous/12'; tasks: {TASKS}",
        ),
        (
            "{robotouille/synchronous/2: 3,",
            "{robotouille/synchronous/2: 3, robotouille/synchronous: 2,",
            E + "methods[2] (recap): step_multipliers: 'robotouille/synchronous/2' (x3) and 'robotouille/synchronous' (x2) "
            "both cover robotouille/synchronous/2_lettuce_tomato_sandwich@42; give each task one multiplier",
        ),
        (
            "{robotouille/synchronous/2: 3,",
            "{robotouille/synchronous/2: 0,",
            E + "methods[2].step_multipliers.robotouille/synchronous/2: 0 is out of range [0.1, 1000]",
        ),
        (
            "    step_multiplier: 2\n",
            "    step_multiplier: true\n",
            E + "methods[1].step_multiplier: must be a number, not true/false",
        ),
        (
            "    step_multiplier: 2\n",
            "    step_multiplier: 5000\n",
            E + "methods[1].step_multiplier: 5000 is out of range [0.1, 1000]",
        ),
    ],
)
def test_bad_multipliers_are_refused_before_anything_runs(tmp_path, capsys, old, new, message):
    assert old in BASE
    assert _refused(tmp_path, capsys, BASE.replace(old, new)) == message


def test_examples_run_each_method_at_the_released_multiplier():
    """examples/paper: every Robotouille unit at paper.step_multiplier(split, task, method) - the
    released configs, cited in reports/paper.py and the example files."""
    seen = set()
    for path in sorted((REPO / "examples" / "paper").glob("*.yaml")):
        spec, _ = load_spec(path)
        if not any(e.benchmark == "robotouille" for e in spec.environments):
            continue  # (swe-verified.yaml needs a data folder to expand; it has no Robotouille unit)
        for u in expand(spec).units:
            bench, split, task = place_of(u.instance_id)
            if bench != "robotouille":
                continue
            want = paper.step_multiplier(split, paper.task_index(task), u.method)
            assert u.step_multiplier == want, (path.name, u.method_label, u.instance_id)
            seen.add((path.name, u.method))
    assert {m for name, m in seen if name == "main-robotouille.yaml"} == {"recap", "adapt", "react", "cot", "act", "standard"}
    assert {name for name, _ in seen} == {"main-robotouille.yaml", "cross-model.yaml", "ablations.yaml"}


def test_the_estimate_measures_each_method_at_its_own_cap():
    """One instance, three caps: the estimate's step budget (calls) follows each method's, not the
    first unit's; Act's whole history (``history: all``) costs more tokens than a 4-message window."""
    from pipeline.estimate import estimate
    from workers.envs.registry import make_env

    text = """run: est
output: /tmp/never-written
models: [{model: offline/expert}]
methods:
  - {method: react, label: x4}
  - {method: react, label: x2, step_multiplier: 2}
  - {method: react, label: x1, step_multipliers: {blocksworld/5: 1}}
  - {method: act, label: all, settings: {history: all}}
  - {method: act, label: window4, settings: {window: 4}}
environments: [{benchmark: blocksworld, instances: [blocksworld/5@1]}]
"""
    plan = expand(parse_spec(text, "sweep.yaml"))
    assert [u.step_multiplier for u in plan.units] == [4.0, 2.0, 1.0, 4.0, 4.0]
    groups = {g.method: g for g in estimate(plan)}
    # blocksworld/5@1's expert plan is 10 steps; ReAct: up to one call per step, plus the first
    assert make_env("blocksworld/5@1").optimal_steps == 10
    assert [groups[k].calls.high for k in ("x4", "x2", "x1")] == [40 + 1, 20 + 1, 10 + 1]
    assert groups["all"].tokens.high > groups["window4"].tokens.high
