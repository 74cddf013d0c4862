"""The ALFWorld benchmark for the registry: list the 134 evaluation games, make one.

Instance ids are ``alfworld/<type>/<game folder>/<trial>`` with the short task type
(``put clean heat cool examine puttwo``), e.g.
``alfworld/heat/pick_heat_then_place_in_recep-Mug-None-Cabinet-10/trial_T20190909_021100_341887``:
stable across machines and data copies, and the path of the game is readable in the id.

Options of :meth:`AlfworldBenchmark.make`:
- ``data_dir``: the primary data folder (game-file version 2.1.1); default ``$ALFWORLD_DATA``.
- ``version``: ``"2.1.1"`` (default, ``put X in/on Y``) or ``"2.1.2"`` (``move X to Y``).
- ``data_dir_2_1_2``: the 2.1.2 folder; default ``$ALFWORLD_DATA_2_1_2``, else
  ``<data_dir>/../alfworld-2.1.2``. Needed to play 2.1.2; also the source of the expert
  walkthroughs (without it, ``expert_plan()`` is None when playing 2.1.1).
- ``max_steps``: environment steps per episode (default 50, the paper's cap).
- ``step_multiplier`` is accepted and has no effect: ALFWorld's cap is a fixed step count.
- ``seed`` is accepted and recorded: the games are deterministic.
- ``show_valid_actions`` (:data:`SHOW_VALID_ACTIONS`): True appends the currently valid actions
  (the admissible commands, in the game's order) to every observation - the first one at reset
  and every one after a step, "Nothing happens." included - as a blank line, the header line
  ``Valid actions:`` and one command per line (:mod:`~workers.envs.alfworld.observation`);
  False shows the game's text alone. The default None means "not decided by the environment":
  the caller fills it per method (:func:`show_valid_actions_for`); left as None it acts as
  False. The environment's one-shot demonstration uses the same setting as its episodes.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any

from recap.config import AgentConfig
from recap.env import Environment
from schemas.labels import ALFWORLD_SPLIT
from workers.envs.alfworld import protocol
from workers.envs.alfworld.data_folders import FOLDER, FOLDER_2_1_2
from workers.envs.alfworld.game_env import AlfworldEnvironment
from workers.envs.alfworld.games import (
    BENCHMARK_NAME,
    Game,
    discover_games,
    load_walkthrough,
    resolve_data_dir,
    resolve_data_dir_2_1_2,
)
from workers.envs.alfworld.observation import check_show_valid_actions
from workers.envs.alfworld.rules import rules_text
from workers.envs.alfworld.task_types import SHORT_NAMES, TASK_TYPES
from workers.envs.alfworld.wording import DEFAULT_VERSION, check_version
from workers.envs.data_sources import DataFolder
from workers.envs.options import EnvOption, episode, run
from workers.envs.registry import Benchmark, DataNotFoundError, EstimateFigures, UnknownInstanceError

DEFAULT_MAX_STEPS = 50
#: about how many characters a game's opening text has (the room's receptacles and the task; the
#: first valid_unseen game's is 344): what ``recap estimate`` assumes instead of resetting a game
OPENING_CHARS = 350
#: the make() option that appends the valid actions to every observation (True / False / None)
SHOW_VALID_ACTIONS = "show_valid_actions"
#: the make() option that decides whether the one-shot demonstration lists them (None: as the episode)
DEMO_VALID_ACTIONS = "demo_valid_actions"
#: agent styles whose ALFWorld observations list the valid actions (see show_valid_actions_for)
STYLES_SHOWING_VALID_ACTIONS = frozenset({"recap"})

#: the options a sweep may give (:mod:`workers.envs.options`). What an episode does: the game-file
#: version, the step cap, the valid actions shown (their default is the method's). How it is
#: run: where the games are read from
ALFWORLD_OPTIONS: Mapping[str, EnvOption] = {
    "data_dir": run(),
    "data_dir_2_1_2": run(),
    "version": episode(DEFAULT_VERSION),
    "max_steps": episode(DEFAULT_MAX_STEPS),
    SHOW_VALID_ACTIONS: episode(),
    DEMO_VALID_ACTIONS: episode(),
}


def show_valid_actions_for(style: str) -> bool:
    """The ``show_valid_actions`` setting for an agent ``style`` (``recap``, ``react``, ...).

    On for ReCAP: the paper's ALFWorld setting exposes the executable actions and its released
    code appends the admissible commands to every observation. Off for every other style: Yao et
    al.'s ReAct/Act ALFWorld prompts show no list, and CoT, Standard and ADaPT follow them.
    Pass the result as ``make(..., show_valid_actions=show_valid_actions_for(style))``; an
    explicit True/False given by a run takes precedence over this choice.
    """
    return style in STYLES_SHOWING_VALID_ACTIONS


#: selectors meaning "every evaluation game"
_ALL = ("all", "eval_out_of_distribution", "valid_unseen")


class AlfworldBenchmark(Benchmark):
    """ALFWorld's registry entry: lists the evaluation games as instances and makes one (options:
    see the module docstring). ``data_dir`` is the data folder used when a call names none."""

    name = BENCHMARK_NAME

    def __init__(self, data_dir: str | os.PathLike[str] | None = None):
        self.data_dir = data_dir

    def declared_options(self) -> Mapping[str, EnvOption]:
        """:data:`ALFWORLD_OPTIONS`."""
        return ALFWORLD_OPTIONS

    def options_for_agent(self, style: str, config: AgentConfig | None = None) -> dict[str, Any]:
        """make() options an agent style runs with unless a sweep sets them (the pipeline asks):
        the method's ``valid_actions`` setting when it has one (the profiles set it for ReAct and
        Act), else the per-style choice of :func:`show_valid_actions_for`."""
        choice = config.valid_actions if config is not None else None
        if choice is None:
            return {SHOW_VALID_ACTIONS: show_valid_actions_for(style)}
        if choice == "episode":
            return {SHOW_VALID_ACTIONS: True, DEMO_VALID_ACTIONS: False}
        return {SHOW_VALID_ACTIONS: choice == "shown"}

    def data_folders(self) -> Mapping[str, DataFolder]:
        """The primary (2.1.1) folder and the optional 2.1.2 one (:mod:`.data_folders`)."""
        return {FOLDER.name: FOLDER, FOLDER_2_1_2.name: FOLDER_2_1_2}

    def place(self, instance_id: str, split: str | None = None, task: str | None = None) -> tuple[str, str]:
        """One split, ``valid_unseen``; the task is the task type, the id's second part
        (``alfworld/heat/...`` -> ``heat``), whatever the environment calls it (the paper's
        tables group by the short type)."""
        parts = instance_id.split("/")
        return (ALFWORLD_SPLIT, parts[1]) if len(parts) > 1 else (split or "", task or "")

    def profile_settings(
        self, config_cls: type[AgentConfig], profile: str, ablation: str | None, generic: dict[str, Any]
    ) -> dict[str, Any]:
        """The methods' profiles on ALFWorld (:mod:`.protocol`)."""
        return protocol.profile_settings(config_cls, profile, generic)

    def release_prompt_settings(self, config_cls: type[AgentConfig]) -> dict[str, Any]:
        """What the authors' released ALFWorld prompts imply (:mod:`.protocol`)."""
        return protocol.release_prompt_settings(config_cls)

    # -- listing --------------------------------------------------------------------------------
    def games(self, selector: str | None = None, *, data_dir: Any = None) -> list[Game]:
        """The games ``selector`` names, in the fixed order (sorted by game path)."""
        games = discover_games(resolve_data_dir(data_dir if data_dir is not None else self.data_dir))
        if selector is None:
            return list(games)
        key = selector.strip()
        if key.startswith(f"{BENCHMARK_NAME}/") and key.count("/") == 1:
            key = key.split("/", 1)[1]  # "alfworld/heat" reads like "heat"
        if key in _ALL or key == BENCHMARK_NAME:
            return list(games)
        if key in TASK_TYPES:
            return [g for g in games if g.short_type == key]
        if key in SHORT_NAMES:
            return [g for g in games if g.task_type == key]
        exact = [g for g in games if g.instance_id == key]
        if exact:
            return exact
        raise UnknownInstanceError(
            f"unknown ALFWorld game or selector {selector!r}; use all, a task type "
            f"({', '.join(TASK_TYPES)}), or a full id such as {games[0].instance_id}"
        )

    def list_instances(self, selector: str | None = None) -> list[str]:
        """The games ``selector`` names in the default data folder."""
        return [g.instance_id for g in self.games(selector)]

    def list_instances_for(self, selector: str | None, options: Mapping[str, Any]) -> list[str]:
        """The games ``selector`` names in ``options['data_dir']`` when a sweep names one."""
        return [g.instance_id for g in self.games(selector, data_dir=options.get("data_dir"))]

    # -- making ---------------------------------------------------------------------------------
    def make(
        self,
        instance_id: str,
        *,
        data_dir: str | os.PathLike[str] | None = None,
        data_dir_2_1_2: str | os.PathLike[str] | None = None,
        version: str = DEFAULT_VERSION,
        max_steps: int = DEFAULT_MAX_STEPS,
        step_multiplier: float | None = None,
        seed: int = 0,
        show_valid_actions: bool | None = None,
        demo_valid_actions: bool | None = None,
        **unknown: Any,
    ) -> Environment:
        if unknown:
            raise ValueError(
                f"unknown ALFWorld option(s) {', '.join(sorted(unknown))}; accepted: data_dir, "
                "data_dir_2_1_2, version, max_steps, step_multiplier, seed, show_valid_actions, demo_valid_actions"
            )
        check_version(version)
        show = check_show_valid_actions(show_valid_actions)
        demo = None if demo_valid_actions is None else check_show_valid_actions(demo_valid_actions, DEMO_VALID_ACTIONS)
        if isinstance(max_steps, bool) or not isinstance(max_steps, int) or max_steps < 1:
            raise ValueError(f"max_steps must be a positive integer, got {max_steps!r}")
        primary = resolve_data_dir(data_dir if data_dir is not None else self.data_dir)
        game = self._one_game(instance_id, primary)
        dir_2_1_2 = resolve_data_dir_2_1_2(primary, data_dir_2_1_2)
        if version == "2.1.2" and dir_2_1_2 is None:
            raise DataNotFoundError(
                "ALFWorld 2.1.2 data not found: set ALFWORLD_DATA_2_1_2 (or pass data_dir_2_1_2=) "
                f"to the alfworld-2.1.2 folder, or place it next to {primary}"
            )
        walkthrough = load_walkthrough(dir_2_1_2, game) if dir_2_1_2 is not None else None
        game_file = game.game_file(dir_2_1_2 if version == "2.1.2" else primary)  # type: ignore[arg-type]
        if not game_file.is_file():
            raise DataNotFoundError(f"ALFWorld game file missing: {game_file}")

        env = AlfworldEnvironment(
            game,
            game_file=game_file,
            primary=primary,
            version=version,
            max_steps=max_steps,
            walkthrough=walkthrough,
            show_valid_actions=show,
            demo_valid_actions=demo,
        )
        env.layout_seed = seed  # no layout: the games are fixed (recorded as given)
        return env

    def estimate_figures(self, instance_id: str, options: Mapping[str, Any]) -> EstimateFigures:
        """The estimate's figures without opening the game: textworld takes seconds to build one at
        reset, minutes for a sweep's 134. No optimal steps (the games are not solved here), the
        fixed step cap, the rules text, :data:`OPENING_CHARS`; a demonstration (one per task type)."""
        max_steps = options.get("max_steps", DEFAULT_MAX_STEPS)
        version = options.get("version", DEFAULT_VERSION)
        return EstimateFigures(None, int(max_steps), rules_text(str(version), int(max_steps)), OPENING_CHARS, True)

    def _one_game(self, instance_id: str, primary: Any) -> Game:
        games = self.games(instance_id, data_dir=primary)
        if len(games) != 1:
            raise UnknownInstanceError(
                f"{instance_id!r} names {len(games)} ALFWorld games; make() needs one full id such as {games[0].instance_id}"
            )
        return games[0]


BENCHMARK = AlfworldBenchmark()
