"""Replay a recorded FEVER trajectory and compare every observation with ours.

A trajectory is a JSON object: ``{"benchmark": "fever", "instance": "fever/<claim id>", "options":
{"wikipedia_url": ...}, "reset": "<first observation>", "steps": [{"action", "observation",
"reward", "done"}, ...]}``. The actions are sent as recorded, at the level of the release's
``WikiEnv`` + ``FeverWrapper`` (no lower-casing: that is the agent-facing layer's). ``options`` may
also hold ``wikipedia`` (``snapshot:DIR``), ``max_steps`` and ``data_dir``; the caller's options
win (a recorded live trajectory checked against a snapshot). :func:`replay_trajectory` gives the
first difference or "N steps identical"; a malformed trajectory raises :class:`TrajectoryError`.
``recap env replay`` tells a FEVER trajectory from a Robotouille one by :func:`is_fever_trajectory`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from workers.envs.registry import get_benchmark

from .claims import BENCHMARK_NAME
from .env import FeverEnvironment

#: the options a trajectory may carry for make()
TRAJECTORY_OPTIONS = ("wikipedia_url", "wikipedia", "max_steps", "data_dir")


class TrajectoryError(ValueError):
    """A trajectory that is not a FEVER trajectory (wrong benchmark, missing or mistyped field)."""


@dataclass(frozen=True)
class ReplayResult:
    """Whether every recorded observation was reproduced, and the first difference or a count."""

    identical: bool
    message: str


def read_trajectory(path: str | Path) -> dict[str, Any]:
    """The trajectory object in ``path``; TrajectoryError for unreadable JSON or a non-object."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise TrajectoryError(f"cannot read FEVER trajectory {str(path)!r}: {exc}") from None
    if not isinstance(raw, dict):
        raise TrajectoryError(f"FEVER trajectory {str(path)!r} is not a JSON object")
    return raw


def is_fever_trajectory(path: str | Path) -> bool:
    """Whether ``path`` holds a JSON object whose ``benchmark`` is ``fever`` (False for anything
    unreadable: the Robotouille reader then says what is wrong with it)."""
    try:
        raw = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(raw, dict) and raw.get("benchmark") == BENCHMARK_NAME


def replay_fever_file(path: str | Path, options: Mapping[str, Any]) -> tuple[bool, str]:
    """(identical?, message) for the trajectory in ``path``, ``options`` overriding its own."""
    result = replay_trajectory(read_trajectory(path), **options)
    return result.identical, result.message


def _checked(traj: Mapping[str, Any]) -> tuple[str, dict[str, Any], list[Mapping[str, Any]]]:
    if traj.get("benchmark") != BENCHMARK_NAME:
        raise TrajectoryError(f"not a FEVER trajectory: benchmark is {traj.get('benchmark')!r}, expected 'fever'")
    instance, options, steps = traj.get("instance"), traj.get("options", {}), traj.get("steps")
    if not isinstance(instance, str):
        raise TrajectoryError("a FEVER trajectory needs 'instance': 'fever/<claim id>'")
    if not isinstance(options, Mapping) or set(options) - set(TRAJECTORY_OPTIONS):
        raise TrajectoryError(f"'options' must be an object with keys among {', '.join(TRAJECTORY_OPTIONS)}, got {options!r}")
    if not isinstance(steps, list):
        raise TrajectoryError("a FEVER trajectory needs 'steps': a list of {action, observation, reward, done}")
    for k, step in enumerate(steps, start=1):
        if (
            not isinstance(step, Mapping)
            or not isinstance(step.get("action"), str)
            or not isinstance(step.get("observation"), str)
        ):
            raise TrajectoryError(f"step {k} needs a string 'action' and a string 'observation'")
    if "reset" in traj and not isinstance(traj["reset"], str):
        raise TrajectoryError("'reset' must be the first observation as a string")
    return instance, dict(options), steps


def replay_trajectory(
    traj: Mapping[str, Any], *, data_dir: str | None = None, wikipedia: str | None = None, **make_options: Any
) -> ReplayResult:
    """Play the recorded actions on a fresh environment; the first observation, reward or ``done`` that
    differs, else "N steps identical". Raises TrajectoryError for a malformed trajectory, the
    environment's errors (WikiError: an answer that cannot be had) as they come."""
    instance, options, steps = _checked(traj)
    if wikipedia is not None:
        options["wikipedia"] = wikipedia
    if data_dir is not None:
        options["data_dir"] = data_dir
    options.update(make_options)
    env = get_benchmark(BENCHMARK_NAME).make(instance, **options)
    assert isinstance(env, FeverEnvironment)
    first = env.reset().observation
    if "reset" in traj and first != traj["reset"]:
        return ReplayResult(False, f"first observation differs: ours {first!r} vs recorded {traj['reset']!r}")
    for k, step in enumerate(steps, start=1):
        label = f"step {k} ({step['action']!r})"
        if env.done:
            return ReplayResult(False, f"{label}: our episode ended after step {k - 1}, the recording goes on")
        ours = env.step(step["action"])
        if ours.observation != step["observation"]:
            return ReplayResult(
                False, f"{label}: observation differs: ours {ours.observation!r} vs recorded {step['observation']!r}"
            )
        if "reward" in step and ours.info["reward"] != step["reward"]:
            return ReplayResult(False, f"{label}: reward is {ours.info['reward']}, recorded {step['reward']}")
        if "done" in step and ours.done != bool(step["done"]):
            return ReplayResult(False, f"{label}: done is {ours.done}, recorded {step['done']}")
    return ReplayResult(True, f"{len(steps)} steps identical")
