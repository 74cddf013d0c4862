"""Open one ALFWorld game with textworld, importing the optional packages only when needed.

``alfworld`` and ``textworld`` are an optional extra: listing games, the demonstrations and the
rules work without them, and the import happens here, when the first real game is opened.
``alfworld`` creates ``$ALFWORLD_DATA`` (default ``~/.cache/alfworld``) on import, so the
variable is pointed at the data folder in use before the import to keep the home folder clean.

textworld's PDDL engine loads a private copy of fast-downward's shared library per game and
never unloads it, so a worker that plays many games in turn would keep ~5 MiB per game it ever
opened; :func:`close_game` hands the copy of a closed game to the next one (see _PlannerPool).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from recap.env import EnvError
from workers.envs.alfworld.games import DATA_ENV
from workers.envs.alfworld.translations import TRANSLATIONS

INSTALL_HINT = "pip install 'recap-eval[alfworld]' (alfworld==0.4.2, textworld 1.7.0)"

# register_game + make + unregister must not interleave between threads (shared registry)
_REGISTRY_LOCK = threading.Lock()


def _import_engine(primary: Path) -> tuple[Any, Any, Any, Any]:
    current = os.environ.get(DATA_ENV)
    if not current or not os.path.isdir(current):
        os.environ[DATA_ENV] = str(primary)
    try:
        import textworld.gym
        from alfworld.agents.environment.alfred_tw_env import AlfredDemangler, AlfredInfos
        from textworld import EnvInfos
    except ImportError as exc:
        missing = (exc.name or "alfworld").split(".")[0]
        raise EnvError(f"ALFWorld games need the optional package {missing!r}, which is not installed: {INSTALL_HINT}") from None
    return textworld.gym, EnvInfos, AlfredDemangler, AlfredInfos


def open_game(game_file: Path, primary: Path, max_steps: int) -> Any:
    """A textworld gym environment for ``game_file`` (not reset yet).

    Requested infos: ``won`` (the success signal) and ``admissible_commands`` (valid actions).
    The demangler without shuffling gives objects their standard names (``mug 3``).
    """
    tw_gym, EnvInfos, AlfredDemangler, AlfredInfos = _import_engine(primary)
    PLANNER_POOL.install()
    TRANSLATIONS.install()  # a game's PDDL translated once per process, not four times per reset
    infos = EnvInfos(won=True, admissible_commands=True, extras=["gamefile"])
    with _REGISTRY_LOCK:
        env_id = tw_gym.register_game(
            str(game_file),
            infos,
            max_episode_steps=max_steps,
            asynchronous=False,
            wrappers=[AlfredDemangler(shuffle=False), AlfredInfos],
        )
        try:
            return tw_gym.make(env_id)
        except Exception as exc:  # textworld raises assorted errors for broken files
            raise EnvError(f"textworld could not open {game_file}: {exc}") from None
        finally:
            tw_gym.registry.pop(env_id, None)  # the env holds its own config; keep no registry entry


class _PlannerPool:
    """Planner library copies of closed games, handed to the next game that is opened.

    textworld gives every game a private copy of fast-downward's library (so concurrent games
    cannot share its global state) and never unloads it. Unloading it ourselves (dlclose) crashed
    the interpreter at exit now and then, so instead a closed game's copy is reused by the next
    game: loading a new task into a copy is what textworld itself does on every reset. The pool
    never holds more copies than games were open at the same time.
    """

    def __init__(self) -> None:
        self._free: list[Any] = []
        self._lock = threading.Lock()

    def install(self) -> None:
        try:
            import fast_downward
        except ImportError:  # textworld reports the missing planner itself when a game starts
            return

        with self._lock:
            if getattr(fast_downward.load_lib, "_from_pool", False):
                return
            load_new = fast_downward.load_lib

            def load_lib() -> Any:
                with self._lock:
                    if self._free:
                        return self._free.pop()
                return load_new()

            load_lib._from_pool = True  # type: ignore[attr-defined]
            fast_downward.load_lib = load_lib

    def give_back(self, lib: Any) -> None:
        with self._lock:
            self._free.append(lib)


PLANNER_POOL = _PlannerPool()


def close_game(env: Any) -> None:
    """Close a game from :func:`open_game` and return its planner library copy to the pool.

    The game's own objects are detached from the library first, so a stray reference to the
    closed game fails loudly instead of touching the next game's planner state.
    """
    engines = list(_pddl_engines(env))  # find them before close() drops the references
    env.close()
    for engine in engines:
        lib = engine.downward_lib
        state = getattr(engine, "_pddl_state", None)
        engine.downward_lib = None
        engine._pddl_state = None
        if state is not None:
            state.downward_lib = None
        PLANNER_POOL.give_back(lib)


def _pddl_engines(env: Any) -> Iterator[Any]:
    """textworld ``PddlEnv`` objects inside the gym env's batch and wrapper layers."""
    todo, seen = [env], set()
    while todo:
        obj = todo.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if getattr(obj, "downward_lib", None) is not None:
            yield obj
            continue
        for attr in ("batch_env", "envs", "_wrapped_env"):
            inner = getattr(obj, attr, None)
            if isinstance(inner, (list, tuple)):
                todo.extend(inner)
            elif inner is not None:
                todo.append(inner)
