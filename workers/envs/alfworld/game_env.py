"""One real ALFWorld game (textworld engine) behind :class:`recap.env.Environment`.

The game accepts any command: a command that is not admissible is still sent, the game answers
"Nothing happens." and its state does not change, and it uses one of the ``max_steps`` steps
(``invalid_action_mode = "step"``), as in the paper's runs. Success is the game's ``won`` flag;
the game never signals a loss, so an episode ends on a win or when the step budget is spent.

With ``show_valid_actions`` every observation (at reset and after every step, "Nothing
happens." included) is followed by the admissible commands, in the game's order (format in
:mod:`~workers.envs.alfworld.observation`); the one-shot demonstration uses the same setting
unless ``demo_valid_actions`` sets its own.
The game shows only what is at the agent's location, so the environment is partially observed.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from recap.env import Demonstration, EnvError, Environment, InvalidActionError, Reset, Step
from workers.envs.alfworld.demos import demonstration_for
from workers.envs.alfworld.engine import close_game, open_game
from workers.envs.alfworld.expert import WalkthroughExpert
from workers.envs.alfworld.games import Game
from workers.envs.alfworld.observation import render_observation
from workers.envs.alfworld.rules import failure_hints_text, rules_text
from workers.envs.alfworld.wording import extract_goal, strip_banner


class AlfworldEnvironment(Environment):
    """One ALFWorld game file as an Environment: any command costs a step (an inadmissible one changes nothing),
    success is the game's ``won`` flag, the episode ends on a win or at ``max_steps``."""

    benchmark = "alfworld"
    invalid_action_mode = "step"
    partially_observed = True

    def __init__(
        self,
        game: Game,
        *,
        game_file: Path,
        primary: Path,
        version: str,
        max_steps: int,
        walkthrough: tuple[str, ...] | None,
        show_valid_actions: bool = False,
        demo_valid_actions: bool | None = None,
    ):
        self.game = game
        self.instance_id = game.instance_id
        self.split = game.short_type
        self.task = game.task_type
        self.version = version
        self.max_steps = max_steps
        self.game_file = game_file
        #: append the valid actions to every observation (resolved: never None here)
        self.show_valid_actions = show_valid_actions
        self.lists_valid_actions = show_valid_actions
        #: whether the one-shot demonstration lists them (None: as the episode does)
        self.demo_valid_actions = show_valid_actions if demo_valid_actions is None else demo_valid_actions
        self._expert = WalkthroughExpert(walkthrough, version) if walkthrough is not None else None
        self._env = open_game(game_file, primary, max_steps)
        self._steps_taken = 0
        self._started = False
        self._done = False

    # -- episode -------------------------------------------------------------------------------
    def reset(self) -> Reset:
        """Start the game over: the opening text without its banner, the admissible commands and the goal;
        EnvError when the text states no goal."""
        obs, info = self._engine(lambda: self._env.reset())
        text = strip_banner(obs)
        goal = extract_goal(text)
        if goal is None:
            raise EnvError(f"{self.instance_id}: the game text has no 'Your task is to:' sentence")
        self._steps_taken = 0
        self._started, self._done = True, False
        if self._expert is not None:
            self._expert.reset()
        valid = tuple(info["admissible_commands"])
        return Reset(observation=render_observation(text, valid, self.show_valid_actions), valid_actions=valid, goal=goal)

    def step(self, action: str) -> Step:
        """Send ``action`` to the game (admissible or not: either way it uses a step); InvalidActionError only
        for a non-string, EnvError before reset or after the end."""
        if not isinstance(action, str):
            raise InvalidActionError(f"an ALFWorld action is a string, got {type(action).__name__}")
        if not self._started:
            raise EnvError(f"{self.instance_id}: call reset() before step()")
        if self._done:
            raise EnvError(f"{self.instance_id}: the episode is over; call reset() to play again")
        obs, _score, engine_done, info = self._engine(lambda: self._env.step(action))
        self._steps_taken += 1
        if self._expert is not None:
            self._expert.observe(action)
        won = bool(info["won"])
        valid = tuple(info["admissible_commands"])
        self._done = won or bool(engine_done) or self._steps_taken >= self.max_steps
        return Step(
            observation=render_observation(obs.strip(), valid, self.show_valid_actions),
            valid_actions=valid,
            done=self._done,
            success=won,
            info={
                "steps": self._steps_taken,
                "max_steps": self.max_steps,
                "won": won,
                "admissible_commands": valid,
            },
        )

    def _engine(self, call: Callable[[], Any]) -> Any:
        if self._env is None:
            raise EnvError(f"{self.instance_id}: the environment is closed; make a new one")
        try:
            return call()
        except EnvError:
            raise
        except Exception as exc:  # the engine's own failures become one error type
            raise EnvError(f"{self.instance_id}: ALFWorld engine failed: {exc!r}") from None

    # -- prompt material ---------------------------------------------------------------------------
    def rules(self) -> str:
        """The rules text for this game version and step cap."""
        return rules_text(self.version, self.max_steps)

    def failure_hints(self) -> str:
        """The same general hints for every game: ALFWorld answers "Nothing happens." without saying what was wrong."""
        return failure_hints_text()

    def demonstration(self) -> Demonstration:
        """The one-shot demonstration for this game's split and version, showing the valid actions when
        ``demo_valid_actions`` says so (by default exactly when this game does)."""
        # the demonstration keeps the default cap: a game played with a tight cap still needs
        # its full demonstration episode to render; it shows the valid actions iff the episode
        # does, unless demo_valid_actions says otherwise (the released ReAct/Act: lists in the
        # episode, none in Yao et al.'s example)
        return demonstration_for(self.split, self.version, show_valid_actions=self.demo_valid_actions)

    def expert_plan(self) -> list[str] | None:
        """The walkthrough's remaining commands; None when the game file has no walkthrough."""
        return None if self._expert is None else self._expert.remaining()

    def close(self) -> None:
        """Close the game engine; the environment cannot be used afterwards (closing twice is harmless)."""
        env, self._env = self._env, None
        if env is not None:
            close_game(env)
