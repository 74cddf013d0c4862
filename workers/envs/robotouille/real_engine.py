"""Optional adapter: the real ``robotouille`` package behind the same Environment interface.

Our engine is the default (``engine: ours``); this adapter exists to cross-check it against the
original where that package can be installed. It drives the real engine through the API the
recorded trajectories name: ``create_robotouille_env(name, seed, noisy_randomization=False)``,
``env.reset()`` and ``env.step([(action, param_arg_dict)])``, with the valid actions read from
the state (``get_valid_actions_and_str``). The real package is not installable in this project's
environment, so this path is untested here; any API mismatch raises EnvError naming it.
"""

from __future__ import annotations

import math
from typing import Any

from recap.env import EnvError, Environment, InvalidActionError, Reset, Step

from . import catalog
from .rules import failure_hints, rules_text

NOT_INSTALLED = "the real robotouille package is not installed; engine: ours is the default"


def make_real_env(ref: catalog.InstanceRef, step_multiplier: float = 4.0) -> Environment:
    """The real engine on instance ``ref`` (``engine: real``); EnvError when the robotouille package or its env
    factory is missing."""
    try:
        import robotouille  # noqa: F401
    except ImportError:
        raise EnvError(NOT_INSTALLED) from None
    try:
        from robotouille.robotouille_env import create_robotouille_env
    except ImportError as exc:
        raise EnvError(f"the installed robotouille package lacks create_robotouille_env ({exc})") from None
    return RealRobotouilleEnv(ref, step_multiplier, create_robotouille_env)


class RealRobotouilleEnv(Environment):
    """The original Robotouille package behind our Environment interface, for cross-checks: invalid actions are
    rejected (no step used), success is the real engine's ``done``."""

    benchmark = "robotouille"
    invalid_action_mode = "reject"

    def __init__(self, ref: catalog.InstanceRef, step_multiplier: float, factory: Any) -> None:
        self.instance_id = ref.instance_id
        self.split, self.task, self.layout_seed = ref.split, ref.task, ref.layout_seed
        self.optimal_steps = ref.optimal_steps
        self.max_steps = math.ceil(ref.optimal_steps * step_multiplier)
        self._factory = factory
        self._env: Any = None
        self._steps_taken = 0
        self._done = False

    def _valid(self) -> list[tuple[Any, str]]:
        try:
            actions, texts = self._env.current_state.get_valid_actions_and_str()
        except AttributeError as exc:
            raise EnvError(f"real robotouille API mismatch: {exc}") from None
        return list(zip(actions, texts))

    def _observation(self, obs: Any) -> str:
        return obs if isinstance(obs, str) else str(obs)

    def reset(self) -> Reset:
        """Create the real environment afresh (no noisy randomization) and return its first observation, valid
        actions and goal."""
        created = self._factory(f"{self.split}/{self.task}", self.layout_seed, noisy_randomization=False)
        self._env = created[0] if isinstance(created, tuple) else created
        obs, _info = self._env.reset()
        self._steps_taken = 0
        self._done = False
        return Reset(self._observation(obs), tuple(t for _, t in self._valid()), self._goal())

    def _goal(self) -> str:
        text = getattr(self._env.current_state, "goal_description", None) or ""
        return str(text)

    def step(self, action: str) -> Step:
        """Take one valid action (InvalidActionError for any other, nothing used); the episode ends on success or
        at ``max_steps``."""
        if self._env is None:
            raise EnvError(f"{self.instance_id}: step() before reset()")
        if self._done:
            raise EnvError(f"{self.instance_id}: the episode is over")
        valid = self._valid()
        match = next((a for a, t in valid if t == action), None)
        if match is None:
            raise InvalidActionError(f"invalid action {action!r}: not one of the {len(valid)} valid actions")
        obs, _reward, done, _info = self._env.step([match])
        self._steps_taken += 1
        success = bool(done)
        self._done = success or self._steps_taken >= self.max_steps
        info = {"steps": self._steps_taken, "max_steps": self.max_steps, "success": success}
        return Step(self._observation(obs), tuple(t for _, t in self._valid()), self._done, success, info)

    def rules(self) -> str:
        """The same rules text our engine gives for this split."""
        return rules_text(self.split)

    def failure_hints(self) -> str:
        """The same failure hints our engine gives."""
        return failure_hints()

    def demonstration(self):
        """None: this cross-check path runs without a demonstration."""
        return None
