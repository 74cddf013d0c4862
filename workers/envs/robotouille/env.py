"""A Robotouille kitchen behind :class:`recap.env.Environment`, on our own engine.

The environment keeps the raw problem and rebuilds the state on ``reset`` (a few milliseconds),
so an environment object can run any number of episodes. Observations are the engine's exact
text (objects, valid actions, goal). An action must be exactly one of the valid actions; anything
else raises InvalidActionError and costs no step. The episode ends when the goal holds after a
step (success) or when ``max_steps`` steps have been taken.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Callable
from typing import Any

from recap.env import Demonstration, EnvError, Environment, InvalidActionError, Reset, Step

from .domain import Domain
from .planner import expert_plan
from .problem import Problem, build_problem
from .rules import failure_hints, rules_text
from .state import Grounding


class RobotouilleEnv(Environment):
    """One Robotouille instance (a kitchen problem) with the benchmark's step cap."""

    benchmark = "robotouille"
    invalid_action_mode = "reject"
    #: every observation ends with its "Valid Actions:" list
    lists_valid_actions = True

    def __init__(
        self,
        *,
        domain: Domain,
        problem_json: dict,
        source: str,
        instance_id: str,
        split: str,
        task: str,
        layout_seed: int,
        optimal_steps: int | None,
        step_multiplier: float = 4.0,
        max_steps: int | None = None,
        demonstration: Callable[[], Demonstration | None] | None = None,
    ) -> None:
        if step_multiplier <= 0:
            raise ValueError(f"step_multiplier must be positive, got {step_multiplier!r}")
        self._domain = domain
        self._problem_json = problem_json
        self._source = source
        self.instance_id = instance_id
        self.split = split
        self.task = task
        self.layout_seed = layout_seed
        self.optimal_steps = optimal_steps
        self.step_multiplier = float(step_multiplier)
        if max_steps is None:
            # the benchmark loop runs while steps < optimal x multiplier (a float)
            max_steps = math.ceil(optimal_steps * step_multiplier) if optimal_steps else 10_000
        self.max_steps = int(max_steps)
        self._demonstration = demonstration
        self._problem: Problem = build_problem(domain, problem_json, source)
        #: the built problem is still at its initial state (reset can reuse it)
        self._pristine = True
        self._steps_taken = 0
        self._done = False
        #: a plan_copy: steps go on after the episode is over
        self._endless = False
        self._started = False
        self._last_rejected: str | None = None

    # ------------------------------------------------------------ properties
    @property
    def goal_description(self) -> str:
        """The goal sentence of the instance, as the observation ends with it."""
        return self._problem.goal_description

    @property
    def state(self):
        """The engine state (read-only use: planners clone it)."""
        return self._problem.state

    @property
    def problem(self) -> Problem:
        """State, goal and goal description of the current episode (read-only use)."""
        return self._problem

    @property
    def done(self) -> bool:
        """Whether the episode is over (solved, or ``max_steps`` taken)."""
        return self._done

    def observation(self) -> str:
        """The current observation text: objects, valid actions and the goal, exactly as the engine writes it."""
        return self._problem.state.observation(self._problem.goal_description)

    def valid_actions(self) -> tuple[str, ...]:
        """The actions valid in the current state, in the engine's order."""
        return self._problem.state.valid_actions()

    # ------------------------------------------------------------ episode
    def reset(self) -> Reset:
        """Rebuild the state from the raw problem (unless it is still untouched) and return the first observation."""
        if not self._pristine:
            self._problem = build_problem(self._domain, self._problem_json, self._source)
        self._pristine = False
        self._steps_taken = 0
        self._done = False
        self._started = True
        self._last_rejected = None
        return Reset(self.observation(), self.valid_actions(), self._problem.goal_description)

    def _grounding(self, action: str) -> Grounding:
        for grounding in self._problem.state.valid_groundings():
            if grounding.text == action:
                return grounding
        self._last_rejected = action
        n = len(self._problem.state.valid_groundings())
        raise InvalidActionError(f"invalid action {action!r}: not one of the {n} valid actions")

    def step(self, action: str) -> Step:
        """Apply ``action``, which must be exactly one of the valid actions (InvalidActionError otherwise, no
        step used); ``info`` says whether the step cap cut the episode (``truncated``)."""
        if not self._started:
            raise EnvError(f"{self.instance_id}: step() before reset()")
        if self._done and not self._endless:
            raise EnvError(f"{self.instance_id}: the episode is over ({self._steps_taken} steps)")
        if not isinstance(action, str):
            raise InvalidActionError(f"invalid action {action!r}: actions are strings")
        grounding = self._grounding(action)
        state = self._problem.state
        state.apply(grounding)
        self._steps_taken += 1
        self._last_rejected = None
        success = self._problem.goal.holds(state)
        done = success or self._steps_taken >= self.max_steps
        self._done = done
        info: dict[str, Any] = {
            "steps": self._steps_taken,
            "max_steps": self.max_steps,
            "success": success,
            "truncated": done and not success,
        }
        return Step(self.observation(), self.valid_actions(), done, success, info)

    def plan_copy(self) -> RobotouilleEnv:
        """A copy that goes on stepping after the goal (the released I/O check steps its engine
        copy through the whole plan, robotouille-baselines/agents/IO_agent.py:174-187)."""
        sim = super().plan_copy()
        assert isinstance(sim, RobotouilleEnv)
        sim._endless = True
        return sim

    # ------------------------------------------------------------ helpers
    def rules(self) -> str:
        """The rules text for this instance's split."""
        return rules_text(self.split)

    def failure_hints(self) -> str:
        """The general hints, plus the closest valid action to the last rejected one when there is a close match."""
        hints = failure_hints()
        if self._last_rejected:
            close = difflib.get_close_matches(self._last_rejected, self.valid_actions(), n=1, cutoff=0.6)
            if close:
                hints += f"\n- The closest valid action is: {close[0]}"
        return hints

    def demonstration(self) -> Demonstration | None:
        """The one-shot demonstration, built on first use; None when this environment was made without one."""
        return self._demonstration() if self._demonstration else None

    def expert_plan(self) -> list[str] | None:
        """Remaining expert actions from the current state ([] once solved; None if out of reach)."""
        if self._done:
            return [] if self.goal_holds() else None
        return expert_plan(self._problem.state, self._problem.goal)

    def goal_holds(self) -> bool:
        """Whether the goal holds in the current state."""
        return self._problem.goal.holds(self._problem.state)
