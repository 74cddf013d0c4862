"""Replay a trajectory recorded on the real engine and compare ours with it step by step.

A trajectory file (``trajectories/T*.json`` in the data folder) holds the problem, the first
observation, and per step the action, the exact observation, the valid actions in engine order,
the true predicates, the special effects in flight and ``done``. ``replay_file`` feeds the same
actions to our engine and reports the first difference, or "N steps identical". It backs the CLI
command ``recap env replay``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from .data import DataFileError, read_json, require, resolve_data_dir
from .domain import load_domain
from .problem import build_problem
from .state import State


def _fact_text(pred: str, row: tuple[str, ...]) -> str:
    return f"{pred}({', '.join(row)})" if len(row) > 1 else f"{pred}({row[0]},)"


def _true_predicates(state: State) -> list[str]:
    return sorted(_fact_text(p, r) for p, r in state.true_facts())


def _first_diff(a: str, b: str) -> str:
    la, lb = a.splitlines(), b.splitlines()
    for k, (x, y) in enumerate(zip(la, lb)):
        if x != y:
            return f"line {k + 1}: ours {x!r} vs recorded {y!r}"
    return f"ours has {len(la)} lines, recorded {len(lb)}"


def _data_dir_for(path: Path, data_dir: str | None) -> Path:
    if data_dir is not None:
        return resolve_data_dir(data_dir)
    # a trajectory inside a data folder (…/trajectories/T1.json) finds its domain next to it
    candidate = path.resolve().parent.parent
    if (candidate / "domain" / "robotouille.json").is_file():
        return candidate
    return resolve_data_dir(None)


def replay_file(path: str, data_dir: str | None = None) -> tuple[bool, str]:
    """(identical?, message): the first difference, or ``"N steps identical"``."""
    file = Path(path)
    raw: Any = read_json(file)
    root = _data_dir_for(file, data_dir)
    problem_json = require(raw, "generated_environment_json", file)
    steps = require(raw, "steps", file)
    initial = require(raw, "initial", file)
    problem = build_problem(load_domain(root), problem_json, str(file))
    state = problem.state
    goal_text = problem.goal_description

    obs = state.observation(goal_text)
    if obs != initial.get("observation"):
        return False, f"initial observation differs: {_first_diff(obs, initial.get('observation', ''))}"
    if "valid_actions" in initial and list(state.valid_actions()) != list(initial["valid_actions"]):
        return False, "initial valid actions differ"
    for k, step in enumerate(steps, start=1):
        if not isinstance(step, dict) or "action" not in step:
            raise DataFileError(f"trajectory {str(file)!r}: step {k} has no action")
        label = f"step {step.get('t', k)} ({step['action']!r})"
        grounding = next((g for g in state.valid_groundings() if g.text == step["action"]), None)
        if grounding is None:
            return False, f"{label}: action is not valid in our engine"
        state.apply(grounding)
        obs = state.observation(goal_text)
        if "observation" in step and obs != step["observation"]:
            return False, f"{label}: observation differs: {_first_diff(obs, step['observation'])}"
        valid = list(state.valid_actions())
        if "valid_actions" in step and valid != list(step["valid_actions"]):
            return False, f"{label}: valid actions differ: ours {valid} vs recorded {step['valid_actions']}"
        done = problem.goal.holds(state)
        if "done" in step and done != bool(step["done"]):
            return False, f"{label}: done is {done}, recorded {step['done']}"
        if "true_predicates" in step and _true_predicates(state) != sorted(step["true_predicates"]):
            ours, rec = set(_true_predicates(state)), set(step["true_predicates"])
            return False, f"{label}: true predicates differ: only ours {sorted(ours - rec)}, only recorded {sorted(rec - ours)}"
        if "special_effects" in step:
            effects = [e.describe() for e in state.effects]
            if effects != step["special_effects"]:
                return False, f"{label}: special effects differ: ours {effects} vs recorded {step['special_effects']}"
    return True, f"{len(steps)} steps identical"
