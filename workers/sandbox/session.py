"""A bash session over a sandbox: what a command leaves in its shell carries over to the next one.

Why: SWE-agent, which the paper's ReCAP runs used (swebench-recap/sweagent/environment/swe_env.py
on SWE-ReX: ``create_session`` :185, ``run_in_session`` :221, ``interrupt_session`` :192-194),
keeps one bash session per episode, so ``cd src`` or ``export FOO=1`` in one call
holds in the next; a sandbox here starts every command afresh in the repository folder. The
session keeps the sandbox's guarantees (each command under its timeout and output cap, nothing
left running after it: :mod:`workers.sandbox.wrapper`, :mod:`workers.sandbox.local_sandbox`) by
carrying the shell's *state* rather than its process: each command runs in one bash that first
restores the state the last command left (working directory, shell variables exported or not,
functions, aliases, ``shopt`` options) and, when it exits, saves its own into a state file
outside the repository (``$TMPDIR`` of the sandbox, ``/tmp`` in a container), so it is never part
of the diff. What does not carry over: background processes (the sandbox stops everything a
command started when it returns) and ``set`` options such as ``-e``.

A command that runs past its timeout is killed before it can save: the session goes on from the
state before that command (it is never wedged), and :meth:`ShellSession.run` says so
(``restored``), for the observation to tell the model.
"""

from __future__ import annotations

import shlex
from dataclasses import dataclass

from workers.sandbox.base import CommandResult, Sandbox

#: the state file, under the sandbox's own temporary folder (evaluated before the state is
#: restored, so a command that changes ``TMPDIR`` does not move it)
STATE_FILE = '"${TMPDIR:-/tmp}/.recap-eval-shell-state"'

#: variables bash sets itself (restoring them fails or changes the shell), and the session's own
_SKIP = (
    "BASH*|EUID|PPID|UID|SHELLOPTS|BASHOPTS|PWD|OLDPWD|SHLVL|_|RANDOM|SRANDOM|LINENO|SECONDS|FUNCNAME|"
    "PIPESTATUS|GROUPS|DIRSTACK|HISTCMD|EPOCHREALTIME|EPOCHSECONDS|COMP_*|HOSTNAME|HOSTTYPE|MACHTYPE|"
    "OSTYPE|IFS|OPTIND|OPTERR|OPTARG|PS4|__recap_*"
)

#: runs before the command, in the same shell: restore the last state, save this one on exit
PRELUDE = f"""__recap_state={STATE_FILE}
if [ -f "$__recap_state" ]; then . "$__recap_state" >/dev/null 2>&1; fi
__recap_save() {{
  local __recap_n __recap_d
  {{
    for __recap_n in $(compgen -v); do
      case "$__recap_n" in {_SKIP}) continue ;; esac
      __recap_d=$(declare -p "$__recap_n" 2>/dev/null) || continue
      [[ ${{__recap_d#declare -}} =~ ^[a-zA-Z]*r ]] && continue
      printf '%s\\n' "$__recap_d"
    done
    for __recap_n in $(compgen -A function); do
      case "$__recap_n" in __recap_*) continue ;; esac
      declare -f "$__recap_n"
    done
    alias -p
    shopt -p
    printf 'cd -- %q\\n' "$PWD"
  }} > "$__recap_state.new" 2>/dev/null && mv -f "$__recap_state.new" "$__recap_state"
}}
trap '__recap_save' EXIT
"""


@dataclass(frozen=True)
class SessionResult:
    """One command's result in the session; ``restored``: the command was killed (timeout), so
    the session goes on from the state before it."""

    result: CommandResult
    restored: bool = False


class ShellSession:
    """The episode's bash session over ``sandbox`` (see the module docstring)."""

    def __init__(self, sandbox: Sandbox) -> None:
        self.sandbox = sandbox

    @staticmethod
    def script(command: str) -> str:
        """The bash script one command runs as: the prelude, then the command itself (``eval``
        in the same shell, so its ``cd`` and assignments stay for the save)."""
        return f"{PRELUDE}eval {shlex.quote(command)}\n"

    def run(self, command: str, *, timeout_s: float | None = None) -> SessionResult:
        """Run ``command`` in the session under the sandbox's limits."""
        res = self.sandbox.run(self.script(command), timeout_s=timeout_s)
        return SessionResult(res, restored=res.timed_out)

    def reset(self) -> None:
        """Forget the session's state (the next command starts in the repository folder)."""
        self.sandbox.run(f"rm -f {STATE_FILE}")
