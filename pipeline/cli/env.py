"""``recap env ...``: look at the benchmarks without any model.

* ``env list BENCH [SELECTOR] [--all]`` - the instance ids a sweep file can name (``--all``: every
  instance, not only the default set: FEVER's claims beyond the paper's 200);
* ``env play ID [--option KEY=VALUE ...]`` - play an instance by hand: type an action (any letter
  case) or its number, see the observation and the step count against the step cap; the options
  are the environment's (FEVER: ``wikipedia_url``, ``wikipedia``, ``data_dir``);
* ``env replay TRAJECTORY.json`` - re-run a recorded Robotouille trajectory on our engine, or a
  FEVER trajectory (``"benchmark": "fever"``, :mod:`workers.envs.fever.replay`) on our FEVER
  environment, and say whether every observation is identical (exit 0 only then);
* ``env standin fever [--port N]`` - serve the benchmark's offline stand-in (FEVER: Wikipedia
  pages in the real layout) until Ctrl-C or SIGTERM.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
from collections.abc import Sequence
from typing import TextIO

from pipeline.cli.common import OneLineParser, finite_positive
from pipeline.errors import PipelineError
from recap.env import DataNotFoundError, EnvError, InvalidActionError, UnknownInstanceError, agent_action
from workers.envs.registry import benchmark_names, get_benchmark, make_env, replay_trajectory_file

_EPILOG = """\
examples:
  recap env list blocksworld 4
  recap env play blocksworld/3@1
  recap env replay trajectory.json
  recap env standin fever --port 8080

No model is involved. Each action's options and examples: recap env ACTION --help.
"""

_LIST_EPILOG = """\
examples:
  recap env list blocksworld                  every instance id
  recap env list blocksworld 4                the ids of 4-block problems
  recap env list robotouille asynchronous
  recap env list alfworld heat
  recap env list fever                        the paper's 200 claims, in the release's order
  recap env list fever --all                  every claim of paper_dev.jsonl

The ids go to stdout, one a line, and their count to stderr. exit status: 0 ok; 2 unknown
benchmark or selector, or its data is missing (recap data --help)
"""

_PLAY_EPILOG = """\
examples:
  recap env play blocksworld/3@1
  recap env play robotouille/synchronous/0_cheese_sandwich@42 --step-multiplier 2
  recap env play fever/168966 --option wikipedia_url=http://localhost:8080

Type an action (any letter case) or its number in the list; quit, exit or q to stop.
exit status: 0 played; 2 unknown instance or missing data
"""

_REPLAY_EPILOG = """\
examples:
  recap env replay trajectory.json
  recap env replay fever-trajectory.json --option wikipedia=snapshot:runs/fever-main

A FEVER trajectory is {"benchmark": "fever", "instance": "fever/<claim id>", "options": {...},
"reset": "<first observation>", "steps": [{"action", "observation", "reward", "done"}, ...]}
(README: FEVER trajectories); --option overrides its options. Anything else is read as a Robotouille
trajectory.
exit status: 0 every observation identical; 1 a difference (printed); 2 unreadable trajectory,
missing data or a page that cannot be had
"""


def add_parser(sub: argparse._SubParsersAction[OneLineParser], name: str, help: str) -> None:  # noqa: A002
    """Add ``recap env`` and its actions (list, play, replay) to the ``recap`` parser."""
    env = sub.add_parser(name, help=help, epilog=_EPILOG, description="Look at the benchmarks without any model.")
    esub = env.add_subparsers(
        dest="env_cmd",
        required=True,
        metavar="ACTION",
        title="actions",
        help="one of the actions below; recap env ACTION --help for its options and examples",
    )
    el = esub.add_parser(
        "list",
        help="instance ids of a benchmark",
        epilog=_LIST_EPILOG,
        description="The instance ids of a benchmark that a sweep file can name.",
    )
    el.add_argument("bench", help=f"one of {', '.join(benchmark_names())}")
    el.add_argument(
        "selector", nargs="?", help="only the ids it selects: a size (blocksworld), a split or task (robotouille, alfworld)"
    )
    el.add_argument(
        "--all", action="store_true", help="every instance, not only the default set (fever: every claim, not the paper's 200)"
    )
    ep = esub.add_parser(
        "play",
        help="play an instance by hand",
        epilog=_PLAY_EPILOG,
        description="Play an instance by hand: see the observation, type actions, watch the step count.",
    )
    ep.add_argument("instance_id", help="an instance id as recap env list prints it (e.g. blocksworld/3@1)")
    ep.add_argument(
        "--step-multiplier",
        type=finite_positive,
        default=4.0,
        metavar="X",
        help="step cap = X times the optimal plan's length (default 4; ALFWorld's and FEVER's caps are fixed)",
    )
    _add_option_argument(ep)
    er = esub.add_parser(
        "replay",
        help="replay a recorded Robotouille or FEVER trajectory",
        epilog=_REPLAY_EPILOG,
        description="Re-run a recorded Robotouille or FEVER trajectory on our engine and compare every observation.",
    )
    er.add_argument("trajectory", help="the recorded trajectory (JSON)")
    _add_option_argument(er)
    es = esub.add_parser(
        "standin",
        help="serve a benchmark's offline stand-in server until stopped (fever: Wikipedia)",
        epilog=_STANDIN_EPILOG,
        description="Serve a benchmark's stand-in server on 127.0.0.1 until Ctrl-C or SIGTERM (fever: a few\n"
        "Wikipedia pages in the real site's layout), to try its sweeps without the network.",
    )
    es.add_argument("bench", choices=sorted(STANDINS), help="the benchmark (" + ", ".join(sorted(STANDINS)) + ")")
    es.add_argument("--port", type=int, default=8080, help="the port on 127.0.0.1 (default 8080; 0: a free one)")


#: benchmark -> its stand-in's ``serve(port)`` (``module:function``), imported when asked for
STANDINS = {"fever": "workers.envs.fever.standin:serve"}

_STANDIN_EPILOG = """\
examples:
  recap env standin fever --port 8080
  recap env play fever/168966 --option wikipedia_url=http://127.0.0.1:8080

exit status: 0 stopped by Ctrl-C or SIGTERM; 2 the port cannot be used
"""


def standin_main(bench: str, port: int) -> int:
    """``recap env standin BENCH --port N``: serve the stand-in until stopped; 0 then."""
    module, _, name = STANDINS[bench].partition(":")
    serve = getattr(importlib.import_module(module), name)
    if not 0 <= port <= 65535:
        raise PipelineError(f"--port must be 0..65535, got {port}")
    try:
        return int(serve(port))
    except OSError as exc:
        raise PipelineError(f"cannot listen on 127.0.0.1:{port}: {exc.strerror or exc}") from None


def _add_option_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--option",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        type=option_pair,
        help="an environment option, repeatable (fever: wikipedia_url=URL, wikipedia=snapshot:DIR, data_dir=DIR); "
        "VALUE is read as JSON when it parses (5, true), else as text",
    )


def option_pair(text: str) -> tuple[str, object]:
    """``KEY=VALUE`` as (key, value): the value as JSON when it parses as JSON, else the text."""
    key, sep, value = text.partition("=")
    if not sep or not key.strip():
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        return key.strip(), json.loads(value)
    except ValueError:
        return key.strip(), value


def execute(args: argparse.Namespace, command: str) -> int:
    """Run the parsed ``recap env`` action on the process's stdin and stdout."""
    if args.env_cmd == "list":
        if args.all and args.selector is not None:
            raise PipelineError(f"give a selector or --all, not both (got {args.selector!r} and --all)")
        return list_main(args.bench, "all" if args.all else args.selector, sys.stdout)
    if args.env_cmd == "play":
        return play_main(args.instance_id, sys.stdin, sys.stdout, args.step_multiplier, dict(args.option))
    if args.env_cmd == "standin":
        return standin_main(args.bench, args.port)
    return replay_main(args.trajectory, sys.stdout, dict(args.option))


def _registry_error(exc: Exception) -> PipelineError:
    return PipelineError(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)


def list_main(bench: str, selector: str | None, out: TextIO) -> int:
    """``recap env list BENCH [SELECTOR]``: instance ids one a line on stdout, the count on stderr; quiet when
    the reader closes the pipe early."""
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
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def match_action(text: str, valid: Sequence[str] | None) -> str:
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


def _show(obs: str, valid: Sequence[str] | None, out: TextIO) -> None:
    print(obs, file=out)
    if valid:
        print("Actions:", file=out)
        for i, a in enumerate(valid, 1):
            print(f"  {i:>2}. {a}", file=out)


def play_main(
    instance_id: str, inp: TextIO, out: TextIO, step_multiplier: float = 4.0, options: dict[str, object] | None = None
) -> int:
    """``recap env play ID``: play one instance by hand from ``inp`` (action text or its number; quit/exit/q or
    end of input stops), the typed action spelled as the agent-facing layer spells it
    (:func:`recap.env.agent_action`); 0 whatever the outcome. ``options`` go to the environment."""
    try:
        env = make_env(instance_id, **{"step_multiplier": step_multiplier, **(options or {})})
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
            try:
                step = env.step(agent_action(env, match_action(action, valid)))
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


def replay_main(path: str, out: TextIO, options: dict[str, object] | None = None) -> int:
    """``recap env replay FILE``: replay a saved FEVER trajectory (``options`` override its own) or
    Robotouille trajectory; exit 0 when it replays as recorded, 1 when it does not."""
    try:
        ok, message = replay_trajectory_file(path, options or {})
    except (EnvError, OSError, ValueError) as exc:  # unreadable or malformed trajectory, missing data
        raise PipelineError(f"cannot replay {path}: {exc}") from None
    print(message, file=out)
    return 0 if ok else 1
