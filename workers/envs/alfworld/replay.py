"""A scripted environment that replays a recorded ALFWorld episode, for demonstrations.

ALFWorld's training games are not part of our data, so each one-shot demonstration is an episode
we wrote: a start text, a goal, and the recorded (action, observation, valid actions) of every
step. Replaying it lets the agent render the demonstration by running itself, exactly like a real
game: a command outside the valid actions gets "Nothing happens." and a step, as in ALFWorld.
A *valid* command other than the recorded one cannot be answered faithfully, so it is an error
(a demonstration's replies that stray from their own recording are a bug to fix, not a game).
The recording holds the game's text only; with ``show_valid_actions`` the replay appends the
valid actions to every observation exactly as the real game environment does (see
:mod:`~workers.envs.alfworld.observation`), so a rendered demonstration looks like the episodes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from recap.env import Demonstration, EnvError, Environment, InvalidActionError, Reset, Step
from workers.envs.alfworld.observation import render_observation

NOTHING_HAPPENS = "Nothing happens."


@dataclass(frozen=True)
class RecordedStep:
    """One recorded step: the command, the game's reply, the valid actions after it, and whether it won the game."""

    action: str
    observation: str
    valid_actions: tuple[str, ...]
    won: bool = False


@dataclass(frozen=True)
class Recording:
    """A written demonstration episode: its task type (``split`` short, ``task`` ALFRED's), the opening text,
    goal and valid actions, and the recorded steps."""

    name: str
    split: str  # short task type, "heat"
    task: str  # ALFRED task type
    observation: str
    goal: str
    valid_actions: tuple[str, ...]
    steps: tuple[RecordedStep, ...]

    @property
    def actions(self) -> list[str]:
        """The recorded commands in order (the winning command list)."""
        return [s.action for s in self.steps]


class ReplayEnvironment(Environment):
    """A recording played back as an Environment with a real game's rules: an invalid command gets "Nothing
    happens." and uses a step; a valid command other than the recorded one raises EnvError."""

    benchmark = "alfworld"
    invalid_action_mode = "step"
    partially_observed = True

    def __init__(
        self,
        recording: Recording,
        *,
        rules: str = "",
        failure_hints: str = "",
        max_steps: int = 50,
        expert: bool = True,
        show_valid_actions: bool = False,
    ):
        self.recording = recording
        self.instance_id = f"alfworld-demo/{recording.split}/{recording.name}"
        self.split = recording.split
        self.task = recording.task
        self.max_steps = max_steps
        self._rules = rules
        self._hints = failure_hints
        self._expert = expert
        self.show_valid_actions = show_valid_actions
        self.lists_valid_actions = show_valid_actions
        self._next = 0
        self._steps_taken = 0
        self._valid: tuple[str, ...] = recording.valid_actions
        self._started = False
        self._done = False

    def reset(self) -> Reset:
        """Start the recording over: its opening text, valid actions and goal."""
        self._next = 0
        self._steps_taken = 0
        self._valid = self.recording.valid_actions
        self._started, self._done = True, False
        observation = render_observation(self.recording.observation, self._valid, self.show_valid_actions)
        return Reset(observation, self._valid, self.recording.goal)

    def step(self, action: str) -> Step:
        """The recorded reply when ``action`` is the next recorded command; "Nothing happens." (a step used) when
        it is not valid; EnvError when it is valid but not the recorded one."""
        if not isinstance(action, str):
            raise InvalidActionError(f"an ALFWorld action is a string, got {type(action).__name__}")
        if not self._started:
            raise EnvError(f"{self.instance_id}: call reset() before step()")
        if self._done:
            raise EnvError(f"{self.instance_id}: the episode is over; call reset() to play again")
        won = False
        if action in self._valid:
            expected = self.recording.steps[self._next] if self._next < len(self.recording.steps) else None
            if expected is None or action != expected.action:
                want = expected.action if expected else "nothing (the recording has ended)"
                raise EnvError(f"{self.instance_id}: replay cannot follow {action!r}; the recording continues with {want!r}")
            self._next += 1
            observation, self._valid, won = expected.observation, expected.valid_actions, expected.won
        else:
            observation = NOTHING_HAPPENS
        self._steps_taken += 1
        self._done = won or self._steps_taken >= self.max_steps
        return Step(
            observation=render_observation(observation, self._valid, self.show_valid_actions),
            valid_actions=self._valid,
            done=self._done,
            success=won,
            info={
                "steps": self._steps_taken,
                "max_steps": self.max_steps,
                "won": won,
                "admissible_commands": self._valid,
            },
        )

    def rules(self) -> str:
        return self._rules

    def failure_hints(self) -> str:
        return self._hints

    def demonstration(self) -> Demonstration | None:
        """None: a demonstration has no demonstration of its own."""
        return None

    def expert_plan(self) -> list[str] | None:
        """The recorded commands not yet played, when built with ``expert=True``; else None."""
        if not self._expert:
            return None
        return [s.action for s in self.recording.steps[self._next :]]


def replay_factory(recording: Recording, **kwargs: object) -> Callable[[], ReplayEnvironment]:
    """A ``make_env`` for :class:`Demonstration`: a fresh replay each call."""
    return lambda: ReplayEnvironment(recording, **kwargs)  # type: ignore[arg-type]
