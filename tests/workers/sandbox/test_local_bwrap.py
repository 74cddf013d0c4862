"""The local sandbox under bubblewrap (issue 35 items 1-4): each escape, disk and symlink attack of
:mod:`tests.workers.sandbox.local_attacks` held; the sandbox refused without bubblewrap unless the
sweep says ``sandbox_trust: none``; files read in bounded memory; committed symlinks kept.

On main's code every attack here went through (``umount /proc`` undid the pid namespace, writes
to ``/tmp`` went to the host's disk, ``read_file`` followed symlinks to the host)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.workers.sandbox import local_attacks as A
from tests.workers.sandbox.conftest import Repo, git
from workers.sandbox import SandboxError, SandboxLimits, SandboxSpec, open_sandbox
from workers.sandbox.base import FileTooLarge, OutsideRepository
from workers.sandbox.local_sandbox import WARNING, LocalSandbox

pytestmark = pytest.mark.usefixtures("bwrap_ready")


@pytest.fixture(scope="module")
def host() -> Iterator[A.Host]:
    with A.host_targets() as h:
        yield h


@pytest.fixture
def sandbox(repo: Repo, labels: dict[str, str]) -> Iterator[LocalSandbox]:
    spec = SandboxSpec(str(repo.path), repo.commit, labels=labels, limits=SandboxLimits(disk_bytes=A.DISK_LIMIT))
    sb = open_sandbox("local", spec)
    assert isinstance(sb, LocalSandbox)
    yield sb
    sb.close()


def test_commands_run_under_bubblewrap_at_the_workdir(sandbox: LocalSandbox) -> None:
    assert "bwrap" in sandbox.confinement and sandbox.workdir == "/repo"
    r = sandbox.run("pwd; cat a.txt; grep CapEff /proc/self/status; echo $HOME $TMPDIR; ls /")
    lines = r.output.splitlines()
    assert lines[:4] == ["/repo", "hello", "CapEff:\t0000000000000000", "/home/sandbox /tmp"]
    # the host's other folders (/work, /mnt, /opt, ...) are absent: the system's, the sandbox's own,
    # /root only when a PATH tool lives there (pyenv's shims, bound read-only)
    assert set(lines[4:]) <= {"bin", "dev", "etc", "home", "lib", "lib32", "lib64", "libx32", "proc", "repo"} | {
        "root",
        "sbin",
        "tmp",
        "usr",
        "var",
    }


@pytest.mark.parametrize("name", list(A.ESCAPES))
def test_escape_attempts_fail(sandbox: LocalSandbox, host: A.Host, name: str) -> None:
    held, detail = A.ESCAPES[name](sandbox, host)
    assert held, f"{name}: {detail}"


@pytest.mark.parametrize("name", list(A.DISK))
def test_every_writable_place_is_bounded(sandbox: LocalSandbox, host: A.Host, name: str) -> None:
    assert "disk-tmpfs" in sandbox.confinement  # root here: the kernel's bound, not the watchdog
    held, detail = A.DISK[name](sandbox, host)
    assert held, f"{name}: {detail}"
    assert sandbox.run("echo alive").output == "alive\n"


@pytest.mark.parametrize("place", ["/tmp", "/var/tmp", "$HOME", "repo", "small files"])
def test_where_no_tmpfs_can_be_mounted_the_watchdog_stops_and_reports_an_overrun(
    repo: Repo, labels: dict[str, str], monkeypatch: pytest.MonkeyPatch, place: str
) -> None:
    """The fallback (a worker that may not mount): the command is stopped and the model told.
    A reactive bound: what a command writes between two looks (0.25 s) gets through first."""
    from workers.sandbox import disk_bound

    monkeypatch.setattr(disk_bound, "can_mount", lambda: False)
    spec = SandboxSpec(str(repo.path), repo.commit, labels=labels, limits=SandboxLimits(disk_bytes=A.DISK_LIMIT))
    with open_sandbox("local", spec) as sb:
        assert isinstance(sb, LocalSandbox) and "disk-tmpfs" not in sb.confinement
        cmd = A.small_files_command(A.DISK_LIMIT)[1] if place == "small files" else A.write_command(place)
        r = sb.run(cmd + "; sleep 5", timeout_s=60)
        assert r.exit_code is None and not r.timed_out
        assert r.output.endswith(f"over the {A.DISK_LIMIT}-byte disk limit]")
        assert sb.run("rm -rf /tmp/recap-big* /var/tmp/recap-big* $HOME/recap-big* recap-big*; echo alive").output == "alive\n"


def test_a_sandbox_left_over_its_limit_takes_a_slow_cleanup_and_stops_a_command_that_writes_more(
    repo: Repo, labels: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Where the watchdog bounds the disk: a cleanup of many files that outlasts its looks is not
    killed for the level it starts from (CI, under load: the ``rm -rf`` after the small-files
    overrun was stopped and the sandbox stayed over its limit); a command adding files while the
    sandbox is over is stopped at the next look."""
    from workers.sandbox import disk_bound

    monkeypatch.setattr(disk_bound, "can_mount", lambda: False)
    spec = SandboxSpec(str(repo.path), repo.commit, labels=labels, limits=SandboxLimits(disk_bytes=A.DISK_LIMIT))
    most = disk_bound.tmpfs_inodes(A.DISK_LIMIT)
    with open_sandbox("local", spec) as sb:
        assert isinstance(sb, LocalSandbox) and "disk-tmpfs" not in sb.confinement
        # over the limit in entries, left there by a command that ended between two looks
        sb.run(f"mkdir -p /tmp/recap-big; cd /tmp/recap-big; touch $(seq -f f%g {most + 500})", timeout_s=60)
        left = disk_bound.tree_usage(sb.root)[1]
        assert left > most
        # adding files while over: stopped at the next look, the entries named in the message
        r = sb.run("for i in $(seq 200); do : > /tmp/recap-big/g$i; sleep 0.01; done; echo done", timeout_s=60)
        assert r.exit_code is None and "done" not in r.output
        assert r.output.endswith(f"files and folders (at most {most}), over the {A.DISK_LIMIT}-byte disk limit]")
        # a cleanup in steps, each step under a look apart, the sandbox still over meanwhile
        r = sb.run("rm -f /tmp/recap-big/f1*; sleep 0.8; rm -rf /tmp/recap-big; echo alive", timeout_s=60)
        assert (r.exit_code, r.output) == (0, "alive\n")
        assert disk_bound.tree_usage(sb.root)[1] < most


@pytest.mark.parametrize("name", list(A.SYMLINKS))
def test_symlinks_leaving_the_repository_are_refused(sandbox: LocalSandbox, host: A.Host, name: str) -> None:
    held, detail = A.SYMLINKS[name](sandbox, host)
    assert held, f"{name}: {detail}"


def test_viewing_two_lines_of_a_big_file_does_not_copy_it(repo: Repo, labels: dict[str, str], host: A.Host) -> None:
    with open_sandbox("local", SandboxSpec(str(repo.path), repo.commit, labels=labels)) as sb:
        assert isinstance(sb, LocalSandbox)
        held, detail = A.view_two_lines_of_a_big_file(sb, host)
    assert held, detail


def test_paths_inside_the_repository_resolve_as_the_sandbox_sees_them(sandbox: LocalSandbox) -> None:
    sandbox.run("mkdir -p d && ln -s /repo/a.txt abs.txt && ln -s d dirlink && ln -s d/new.txt dangling.txt")
    assert sandbox.read_file("abs.txt") == b"hello\n"
    assert sandbox.read_file("/repo/abs.txt") == b"hello\n"
    sandbox.write_file("dirlink/x.txt", b"via link\n")
    assert sandbox.run("cat d/x.txt").output == "via link\n"
    sandbox.write_file("dangling.txt", b"made\n")  # a dangling link inside: written where it points
    assert sandbox.run("cat d/new.txt; test -L dangling.txt && echo link").output == "made\nlink\n"
    for bad in ("/etc/passwd", "../a.txt", "/repo/../etc/passwd", "d/../../x"):
        with pytest.raises(OutsideRepository):
            sandbox.read_file(bad)
    with pytest.raises(FileNotFoundError):
        sandbox.read_file("d/missing.txt")
    with pytest.raises(IsADirectoryError):
        sandbox.read_file("dirlink")


def test_read_file_and_read_lines_bounds(sandbox: LocalSandbox) -> None:
    sandbox.write_file("f.txt", b"one\ntwo\nthree")
    with pytest.raises(FileTooLarge) as info:
        sandbox.read_file("f.txt", max_bytes=5)
    assert (info.value.path, info.value.size, info.value.limit) == ("f.txt", 13, 5)
    assert sandbox.read_file("f.txt", max_bytes=13) == b"one\ntwo\nthree"
    s = sandbox.read_lines("f.txt", 2, 3, 100)
    assert (s.data, s.total_lines, s.total_bytes, s.truncated) == (b"two\nthree", 3, 13, False)
    s = sandbox.read_lines("f.txt", 1, None, 6)
    assert (s.data, s.truncated) == (b"one\ntw", True)
    sandbox.write_file("g.txt", b"a\nb\n")
    s = sandbox.read_lines("g.txt", 3, 9, 100)
    assert (s.data, s.total_lines, s.total_bytes) == (b"", 2, 4)


def test_committed_symlinks_stay_symlinks(tmp_path: Path, labels: dict[str, str], monkeypatch: pytest.MonkeyPatch) -> None:
    """Even where the host's git says ``core.symlinks = false`` (the clone would write files
    holding the targets' paths, which the sandbox could not tell from content)."""
    p = tmp_path / "linked"
    p.mkdir()
    git("init", "-q", cwd=p)
    (p / "target.txt").write_text("t\n")
    (p / "rel").symlink_to("target.txt")
    (p / "host").symlink_to("/etc/passwd")
    git("add", ".", cwd=p)
    git("commit", "-qm", "links", cwd=p)
    (tmp_path / "gitconfig").write_text("[core]\n\tsymlinks = false\n")
    monkeypatch.setenv("GIT_CONFIG_GLOBAL", str(tmp_path / "gitconfig"))
    with open_sandbox("local", SandboxSpec(str(p), git("rev-parse", "HEAD", cwd=p), labels=labels)) as sb:
        assert sb.run("readlink rel; readlink host").output == "target.txt\n/etc/passwd\n"
        assert sb.read_file("rel") == b"t\n"
        with pytest.raises(OutsideRepository):
            sb.read_file("host")


def test_without_bubblewrap_local_is_refused_unless_trust_none(
    repo: Repo, labels: dict[str, str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from workers.sandbox import bwrap, check_ready

    monkeypatch.setattr(bwrap, "probe", lambda: "bubblewrap (bwrap) is not installed")
    spec = SandboxSpec(str(repo.path), repo.commit, labels=labels)
    want = (
        "sandbox: local confines the model's commands with bubblewrap, and bubblewrap (bwrap) is not installed: "
        "install it (apt-get install bubblewrap) or set the swe option sandbox_trust: none to run them unconfined on this host"
    )
    for call in (lambda: open_sandbox("local", spec), lambda: check_ready("local", "img")):
        with pytest.raises(SandboxError) as info:
            call()
        assert str(info.value) == want
    with open_sandbox("local", spec, trust="none") as sb:
        assert isinstance(sb, LocalSandbox)
        assert sb.warning == WARNING and "bwrap" not in sb.confinement
        assert sb.run("cat a.txt").output == "hello\n"


@pytest.mark.parametrize("workdir", ["/", "/tmp", "/usr/src", "/home", "relative", "/etc"])
def test_a_workdir_over_the_sandboxes_own_folders_is_refused(repo: Repo, labels: dict[str, str], workdir: str) -> None:
    with pytest.raises(SandboxError, match="^a local sandbox's workdir must be a folder of its own"):
        open_sandbox("local", SandboxSpec(str(repo.path), repo.commit, labels=labels, workdir=workdir))
