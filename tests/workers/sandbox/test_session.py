"""The bash session over a sandbox (workers/sandbox/session.py), on both kinds: what a command
leaves in its shell (directory, variables, functions, aliases) holds in the next; a command that
times out does not wedge it (the state before it stays); the state never enters the repository."""

from __future__ import annotations

from collections.abc import Callable

from workers.sandbox import Sandbox
from workers.sandbox.session import ShellSession

Open = Callable[..., Sandbox]


def _out(session: ShellSession, command: str) -> tuple[int | None, str]:
    ran = session.run(command)
    return ran.result.exit_code, ran.result.output


def test_cd_export_variables_functions_and_aliases_persist(open_kind: Open) -> None:
    sb = open_kind()
    s = ShellSession(sb)
    setup = "mkdir -p pkg/sub && cd pkg/sub && export FOO=bar && x=1 && f() { echo fn$1; }"
    assert _out(s, setup) == (0, "")
    assert _out(s, "shopt -s expand_aliases && alias ll='echo aliased'") == (0, "")
    assert _out(s, 'pwd; echo "$FOO $x"; f 2; ll; env | grep ^FOO=') == (
        0,
        f"{sb.workdir}/pkg/sub\nbar 1\nfn2\naliased\nFOO=bar\n",
    )
    # a fresh command outside the session starts in the repository folder, without the variable
    assert (sb.run('pwd; echo "${FOO-unset}"').output) == f"{sb.workdir}\nunset\n"


def test_exit_status_is_kept_and_state_is_saved_on_exit(open_kind: Open) -> None:
    s = ShellSession(open_kind())
    assert _out(s, "export FOO=baz; exit 3") == (3, "")
    assert _out(s, "echo $FOO") == (0, "baz\n")
    assert _out(s, "unset FOO; echo ${FOO-unset}") == (0, "unset\n")
    assert _out(s, "echo ${FOO-unset}") == (0, "unset\n")
    assert _out(s, "y=$'two\\nlines'") == (0, "")
    assert _out(s, 'printf "%s" "$y" | wc -l') == (0, "1\n")


def test_a_timed_out_command_leaves_the_state_before_it_and_the_session_goes_on(open_kind: Open) -> None:
    sb = open_kind(command_timeout_s=2)
    s = ShellSession(sb)
    assert _out(s, "mkdir d && cd d && export KEEP=1") == (0, "")
    ran = s.run("cd / && export KEEP=2 && sleep 30")
    assert (ran.result.timed_out, ran.result.exit_code, ran.restored) == (True, None, True)
    assert _out(s, "pwd; echo $KEEP") == (0, f"{sb.workdir}/d\n1\n")


def test_the_session_state_is_not_in_the_repository_and_reset_forgets_it(open_kind: Open) -> None:
    sb = open_kind()
    s = ShellSession(sb)
    assert _out(s, "mkdir e && cd e && export Z=9") == (0, "")
    assert sb.run("git status --porcelain --untracked-files=all").output == ""  # the empty folder is not tracked
    s.reset()
    assert _out(s, 'pwd; echo "${Z-unset}"') == (0, f"{sb.workdir}\nunset\n")
