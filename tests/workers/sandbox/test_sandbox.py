"""Both sandbox kinds against the same behaviour: commands, limits, files, git, cleanup.

Docker-only cases (what needs isolation: ``rm -rf /``, writes outside the repository) are in
test_docker_sandbox.py; the local sandbox never runs those on the host.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from tests.workers.sandbox.conftest import Repo
from workers.sandbox import Sandbox

Open = Callable[..., Sandbox]


def test_round_trip_exit_codes_and_interleaved_output(open_kind: Open) -> None:
    sb = open_kind()
    r = sb.run("echo out; echo err >&2; echo out2; exit 3")
    assert (r.exit_code, r.output, r.output_bytes, r.timed_out, r.truncated) == (3, "out\nerr\nout2\n", 13, False, False)
    r = sb.run("printf 'a b'")
    assert (r.exit_code, r.output, r.output_bytes) == (0, "a b", 3)
    r = sb.run("false")
    assert (r.exit_code, r.output) == (1, "")


def test_repository_at_base_commit_in_workdir(open_kind: Open, repo: Repo) -> None:
    sb = open_kind()
    r = sb.run("cat a.txt; git rev-parse HEAD; git status --porcelain; git remote; pwd")
    assert r.exit_code == 0
    assert r.output == f"hello\n{repo.commit}\n{sb.workdir}\n"


def test_output_cap_cuts_exactly_and_counts_everything(open_kind: Open) -> None:
    sb = open_kind(output_bytes=10)
    r = sb.run("printf '0123456789ABCDEF'; exit 4")
    assert (r.exit_code, r.output, r.output_bytes, r.truncated) == (4, "0123456789", 16, True)
    r = sb.run("yes | head -c 1000000")
    assert (r.exit_code, r.output, r.output_bytes, r.truncated) == (0, "y\n" * 5, 1_000_000, True)
    r = sb.run("printf '0123456789'")
    assert (r.output, r.output_bytes, r.truncated) == ("0123456789", 10, False)


@pytest.mark.host_load
@pytest.mark.parametrize("command", ["sleep 1000", "yes > /dev/null", "bash -c 'trap \"\" TERM INT; sleep 1000'"])
def test_timeout_kills_the_command_and_the_next_one_works(open_kind: Open, command: str) -> None:
    sb = open_kind()
    r = sb.run(command, timeout_s=1)
    assert (r.exit_code, r.timed_out) == (None, True)
    assert r.duration_s < 30  # killed, not waited for (a bound, not a speed figure)
    assert (sb.run("echo ok").exit_code, sb.run("echo ok").output) == (0, "ok\n")


@pytest.mark.host_load
def test_nothing_outlives_its_command(open_kind: Open) -> None:
    sb = open_kind()
    r = sb.run("sleep 1000 & setsid sleep 999 & echo started")
    assert (r.exit_code, r.output, r.timed_out) == (0, "started\n", False)
    r = sb.run("cat /proc/[0-9]*/cmdline | tr '\\0' ' ' | grep -c 'sleep 99[09]'")
    assert r.output == "0\n"


@pytest.mark.host_load
def test_fork_bomb_is_stopped_and_the_sandbox_still_answers(open_kind: Open) -> None:
    sb = open_kind(pids=64)
    if sb.kind == "local" and not {"pids-cgroup", "pid-namespace"} <= set(getattr(sb, "confinement", ())):
        pytest.skip("this host gives the local sandbox no pids cgroup + pid namespace: a fork bomb would hit the host")
    r = sb.run(":(){ :|:& };:", timeout_s=5)
    assert r.exit_code is not None or r.timed_out
    r = sb.run("echo alive")
    assert (r.exit_code, r.output) == (0, "alive\n")


def test_host_environment_is_not_visible(open_kind: Open, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("OPENAI_API_KEY", "sk-test-secret")
    sb = open_kind(env={"TASK_VAR": "given"})
    r = sb.run("env")
    assert r.exit_code == 0 and not r.truncated
    assert "sk-test-secret" not in r.output and "OPENAI_API_KEY" not in r.output
    names = {line.split("=", 1)[0] for line in r.output.splitlines()}
    assert "TASK_VAR=given" in r.output.splitlines()
    assert {"PATH", "HOME", "LANG"} <= names


def test_network_is_off(open_kind: Open) -> None:
    sb = open_kind()
    if sb.kind == "local" and "no-network" not in getattr(sb, "confinement", ()):
        pytest.skip("unshare --net is not available here: the local sandbox cannot turn the network off")
    r = sb.run("python3 -c \"import socket; socket.create_connection(('10.255.255.53', 53), 2)\"")
    assert r.exit_code == 1
    assert "Network is unreachable" in r.output


def test_read_and_write_files(open_kind: Open) -> None:
    sb = open_kind()
    assert sb.read_file("a.txt") == b"hello\n"
    sb.write_file("sub/dir/new.bin", b"\x00\xffbin")
    assert sb.read_file("sub/dir/new.bin") == b"\x00\xffbin"
    assert sb.read_file(f"{sb.workdir}/sub/dir/new.bin") == b"\x00\xffbin"
    assert sb.run("od -An -tx1 sub/dir/new.bin").output.split() == ["00", "ff", "62", "69", "6e"]
    sb.write_file("a.txt", b"replaced\n")
    assert sb.read_file("a.txt") == b"replaced\n"
    sb.run("ln -s a.txt link.txt")
    assert sb.read_file("link.txt") == b"replaced\n"
    with pytest.raises(FileNotFoundError):
        sb.read_file("missing.txt")
    with pytest.raises(IsADirectoryError):
        sb.read_file("sub")


def test_git_diff_shows_an_edit_and_commits_work(open_kind: Open) -> None:
    sb = open_kind()
    sb.write_file("a.txt", b"changed\n")
    r = sb.run("git diff")
    assert r.exit_code == 0
    assert "\n-hello\n+changed\n" in r.output
    r = sb.run("git commit -qam edit && git log --format='%an <%ae>|%s' -1")
    assert (r.exit_code, r.output) == (0, "recap-eval sandbox <sandbox@recap-eval.invalid>|edit\n")


@pytest.mark.host_load
def test_disk_limit_is_reported(open_kind: Open) -> None:
    sb = open_kind(disk_bytes=1_000_000)
    r = sb.run("head -c 3000000 /dev/zero > big.bin; echo done")
    if getattr(sb, "disk_bound", None) == "read-only+tmpfs":
        # the repository is a tmpfs of disk_bytes (issue 35 item 3): the write itself is stopped
        assert (r.exit_code, r.output) == (0, "head: error writing 'standard output': No space left on device\ndone\n")
        assert int(sb.run("stat -c %s big.bin").output) <= 1_000_000
    else:
        assert r.exit_code is None
        assert "over the 1000000-byte disk limit]" in r.output
    assert sb.run("rm big.bin && echo ok").output == "ok\n"


def test_close_is_idempotent_and_refuses_later_use(open_kind: Open) -> None:
    from workers.sandbox import SandboxError

    sb = open_kind()
    sb.close()
    sb.close()
    with pytest.raises(SandboxError, match="^the sandbox is closed$"):
        sb.run("true")


def test_local_sandbox_says_what_confines_it(repo: Repo, labels: dict[str, str]) -> None:
    """Under bubblewrap the warning names it; the unconfined fallback (sandbox_trust: none) says
    it is NOT isolation; the temporary root goes with close."""
    from workers.sandbox import SandboxSpec, open_sandbox
    from workers.sandbox.local_sandbox import WARNING, WARNING_BWRAP, LocalSandbox

    with open_sandbox("local", SandboxSpec(str(repo.path), repo.commit, labels=labels)) as sb:
        assert isinstance(sb, LocalSandbox)
        assert sb.warning == (WARNING_BWRAP if "bwrap" in sb.confinement else WARNING)
        assert "NOT isolation" in WARNING and "bubblewrap" in WARNING_BWRAP
        root = Path(sb.root)
        assert root.is_dir()
    assert not root.exists()
