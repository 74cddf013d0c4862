"""``recap env ...``: look at the benchmarks without any model.

* ``env list BENCH [SELECTOR]`` - the instance ids a sweep file can name;
* ``env play ID`` - play an instance by hand: type an action (any letter case) or its number, see
  the observation and the step count against the step cap;
* ``env replay TRAJECTORY.json`` - re-run a recorded Robotouille trajectory on our engine and say
  whether every observation is identical (exit 0 only then).
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

from pipeline.errors import PipelineError
from recap.env import EnvError


def _registry_error(exc: Exception) -> PipelineError:
    return PipelineError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)


def list_main(bench: str, selector: str | None, out: TextIO) -> int:
    """``recap env list BENCH [SELECTOR]``: instance ids one a line on stdout, the count on stderr; quiet when
    the reader closes the pipe early."""
    from recap.env import DataNotFoundError, EnvError, UnknownInstanceError
    from workers.envs.registry import get_benchmark

    try:
        ids = get_benchmark(bench).list_instances(selector)
    except (UnknownInstanceError, DataNotFoundError, EnvError, ValueError) as exc:
        raise _registry_error(exc) from None
    except (ImportError, AttributeError) as exc:
        raise PipelineError(f"benchmark {bench!r} is not available here ({exc})") from None
    try:
        for i in ids:
            print(i, file=out)
        out.flush()
    except BrokenPipeError:
        # `recap env list ... | head`: the reader has what it wanted; say nothing more
        _silence_stdout()
        return 0
    print(f"{len(ids)} instance{'s' if len(ids) != 1 else ''}", file=sys.stderr)
    return 0


def _silence_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so the interpreter's final flush is quiet."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def match_action(text: str, valid: Any) -> str:
    """The valid action ``text`` names: its number in the list, or the action in any letter case
    and spacing. Anything else is returned unchanged (the environment rejects it)."""
    if not valid:
        return text
    if text.isdigit() and 1 <= int(text) <= len(valid):
        return valid[int(text) - 1]
    wanted = " ".join(text.split()).casefold()
    for a in valid:
        if " ".join(a.split()).casefold() == wanted:
            return a
    return text


def _show(obs: str, valid: Any, out: TextIO) -> None:
    print(obs, file=out)
    if valid:
        print("Actions:", file=out)
        for i, a in enumerate(valid, 1):
            print(f"  {i:>2}. {a}", file=out)


def play_main(instance_id: str, inp: TextIO, out: TextIO, step_multiplier: float = 4.0) -> int:
    """``recap env play ID``: play one instance by hand from ``inp`` (action text or its number; quit/exit/q or
    end of input stops); 0 whatever the outcome."""
    from recap.env import DataNotFoundError, EnvError, InvalidActionError, UnknownInstanceError
    from workers.envs.registry import make_env

    try:
        env = make_env(instance_id, step_multiplier=step_multiplier)
    except (UnknownInstanceError, DataNotFoundError, EnvError, ValueError) as exc:
        raise _registry_error(exc) from None
    except (ImportError, AttributeError) as exc:
        raise PipelineError(f"cannot load {instance_id!r}: {exc}") from None
    try:
        r = env.reset()
        if f"Goal: {r.goal}" not in r.observation:  # Robotouille's observation ends with it already
            print(f"Goal: {r.goal}", file=out)
        _show(r.observation, r.valid_actions, out)
        print(f"Step 0 of {env.max_steps}", file=out)
        valid = r.valid_actions
        while True:
            print("> ", end="", file=out, flush=True)
            line = inp.readline()
            if not line:
                print("(end of input)", file=out)
                return 0
            action = line.strip()
            if action in ("quit", "exit", "q"):
                return 0
            if not action:
                continue
            action = match_action(action, valid)
            try:
                step = env.step(action)
            except InvalidActionError as exc:
                print(f"Invalid action: {exc}", file=out)
                hints = env.failure_hints()
                if hints:
                    print(hints, file=out)
                continue
            valid = step.valid_actions
            _show(step.observation, valid, out)
            print(f"Step {env.steps_taken} of {env.max_steps}", file=out)
            if step.done:
                print(f"Episode over after {env.steps_taken} steps: {'SUCCESS' if step.success else 'not solved'}", file=out)
                return 0
    finally:
        env.close()


def replay_main(path: str, out: TextIO) -> int:
    """``recap env replay FILE``: replay a saved Robotouille trajectory; exit 0 when it replays as recorded, 1
    when it does not."""
    from workers.envs.robotouille.replay import replay_file

    try:
        ok, message = replay_file(path)
    except (EnvError, OSError, ValueError) as exc:  # unreadable or malformed trajectory, missing data
        raise PipelineError(f"cannot replay {path}: {exc}") from None
    print(message, file=out)
    return 0 if ok else 1
