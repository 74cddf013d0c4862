"""Attacks a model can make through the coding tools on a docker sandbox (issue 35 items 2-5),
one function each, shared by the pytest tests (test_hostile_tools.py) and the chaos lab's
``sandbox_docker`` scenario (tests/pipeline/chaos/sandbox_docker.py).

Each attack takes an environment reset on :func:`hostile_repo`'s task (or, for the disk, a
folder to build a sandbox in) and returns ``(held, detail)``: held when the tool refused or
stayed inside its bounds, the episode went on (no ``done``, no raise), and nothing outside the
repository was read or changed.
"""

from __future__ import annotations

import json
import os
import subprocess
import tracemalloc
import uuid
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from workers.envs.registry import make_env
from workers.envs.swe.env import SweEnvironment
from workers.envs.swe.examples import make_fixtures
from workers.sandbox import LABEL_RUN, Sandbox, SandboxLimits, SandboxSpec, open_sandbox, remove_labelled

Attack = Callable[[SweEnvironment], tuple[bool, str]]

#: the committed links of the hostile repository: name -> target
LINKS = {
    "passwd": "/etc/passwd",  # a container file outside the repository
    "etc": "/etc",  # a folder outside
    "tmpdir": "/tmp",  # a writable folder outside
    "gone": "/nonexistent/dir",  # dangling, outside
    "later": "newdir",  # dangling, inside: a create through it lands in the repository
}
#: lines of the 19 MB file the memory attack views two lines of
BIG_LINES = 2_600_000


def hostile_repo(folder: Path) -> Path:
    """The ``twofiles`` fixture task with :data:`LINKS` committed (the tasks file's base commit
    moved to that commit); returns the tasks file."""
    fx = make_fixtures(folder, ("twofiles",))
    repo = fx.tasks_file.parent / "repos" / "twofiles"
    for name, target in LINKS.items():
        os.symlink(target, repo / name)
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "add", "-A"], cwd=repo, check=True)
    subprocess.run([*git, "commit", "-qm", "links"], cwd=repo, check=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, check=True, capture_output=True, text=True).stdout.strip()
    rows = [json.loads(line) for line in fx.tasks_file.read_text().splitlines() if line.strip()]
    for row in rows:
        row["base_commit"] = head
    fx.tasks_file.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return fx.tasks_file


def docker_env(tasks_file: Path, labels: dict[str, str], **options: Any) -> SweEnvironment:
    """An environment on the hostile task with a docker sandbox (reset)."""
    env = make_env(
        "swe/fixture__twofiles-1",
        instances_file=str(tasks_file),
        open_sandbox=lambda spec: open_sandbox("docker", replace(spec, labels={**spec.labels, **labels})),
        **options,
    )
    assert isinstance(env, SweEnvironment)
    env.reset()
    return env


def _call(env: SweEnvironment, name: str, **args: Any) -> tuple[str, str | None, bool]:
    """(observation, error, episode went on) of one tool call; a raise is not caught: it is the failure."""
    step = env.call_tool(name, args)
    return step.observation, step.info.get("error"), not step.done


def _sh(env: SweEnvironment, command: str) -> str:
    return env._box().run(command).output


def _refused(env: SweEnvironment, name: str, expected: str, **args: Any) -> tuple[bool, str]:
    """Held when the call is refused with exactly ``expected`` and the episode goes on."""
    obs, error, going = _call(env, name, **args)
    expected = expected.format(root=env.workdir)
    return (error == expected and obs == f"Error: {expected}" and going), f"{obs[:200]!r}"


# -- item 2: symbolic links -------------------------------------------------------------------


def view_link_to_a_container_file(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(
        env, "view", "view: {root}/passwd leads outside the repository {root} (through a symbolic link)", path="passwd"
    )


def view_through_a_linked_folder(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(
        env, "view", "view: {root}/etc/passwd leads outside the repository {root} (through a symbolic link)", path="etc/passwd"
    )


def list_a_linked_folder(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(env, "view", "view: {root}/etc leads outside the repository {root} (through a symbolic link)", path="etc")


def create_through_a_linked_folder(env: SweEnvironment) -> tuple[bool, str]:
    held, detail = _refused(
        env,
        "create",
        "create: {root}/tmpdir/evil.py leads outside the repository {root} (through a symbolic link)",
        path="tmpdir/evil.py",
        file_text="x = 1\n",
    )
    landed = _sh(env, "test -e /tmp/evil.py && echo LANDED || echo absent").strip()
    return held and landed == "absent", f"{detail}; /tmp/evil.py {landed}"


def str_replace_through_a_link(env: SweEnvironment) -> tuple[bool, str]:
    before = _sh(env, "md5sum /etc/passwd")
    held, detail = _refused(
        env,
        "str_replace",
        "str_replace: {root}/passwd leads outside the repository {root} (through a symbolic link)",
        path="passwd",
        old_str="root",
        new_str="toor",
    )
    return held and _sh(env, "md5sum /etc/passwd") == before, detail


def links_stay_links(env: SweEnvironment) -> tuple[bool, str]:
    """The repository copied into the container keeps its links as links (not their targets' bytes)."""
    out = _sh(env, "for f in passwd etc tmpdir gone later; do printf '%s ' \"$(readlink $f)\"; done")
    want = " ".join(LINKS.values()) + " "
    return out == want, repr(out)


def undo_a_create_after_its_folder_became_a_link_out(env: SweEnvironment) -> tuple[bool, str]:
    """undo_edit of a created file removes it only inside the repository: a folder on the way
    swapped for a link out of it since then is refused, the file it now points at kept."""
    _call(env, "create", path="made/keep.py", file_text="x = 1\n")
    _sh(env, "rm -rf made && ln -s /tmp made && echo precious > /tmp/keep.py")
    held, detail = _refused(
        env,
        "undo_edit",
        "undo_edit: {root}/made/keep.py leads outside the repository {root} (through a symbolic link)",
        path="made/keep.py",
    )
    kept = _sh(env, "cat /tmp/keep.py")
    return held and kept == "precious\n", f"{detail}; /tmp/keep.py holds {kept!r}"


# -- item 5: tools never raise ----------------------------------------------------------------


def create_through_a_dangling_link_out(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(
        env,
        "create",
        "create: {root}/gone/x.py leads outside the repository {root} (through a symbolic link)",
        path="gone/x.py",
        file_text="x = 1\n",
    )


def create_through_a_dangling_link_in(env: SweEnvironment) -> tuple[bool, str]:
    """A dangling link inside the repository: the file is created where the link points."""
    obs, error, going = _call(env, "create", path="later/x.py", file_text="x = 1\n")
    landed = _sh(env, "cat newdir/x.py")
    return (error is None and going and landed == "x = 1\n"), f"{obs!r}; newdir/x.py holds {landed!r}"


def path_with_a_nul_byte(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(env, "view", "view: the path 'units.py\\x00.txt' contains a NUL byte", path="units.py\x00.txt")


def path_too_long(env: SweEnvironment) -> tuple[bool, str]:
    path = "a/" * 3000 + "x.py"
    shown = path[:120] + "..."
    return _refused(
        env,
        "create",
        f"create: the path is {len(path)} bytes long, over the 4096-byte limit ({shown!r})",
        path=path,
        file_text="x",
    )


def view_a_fifo(env: SweEnvironment) -> tuple[bool, str]:
    _sh(env, "mkfifo pipe")
    return _refused(env, "view", "view: {root}/pipe is not a regular file (a fifo, a device or a socket)", path="pipe")


def edit_a_fifo(env: SweEnvironment) -> tuple[bool, str]:
    _sh(env, "mkfifo pipe2")
    return _refused(
        env,
        "str_replace",
        "str_replace: {root}/pipe2 is not a regular file (a fifo, a device or a socket)",
        path="pipe2",
        old_str="a",
    )


def view_a_device_through_a_link(env: SweEnvironment) -> tuple[bool, str]:
    _sh(env, "ln -s /dev/zero zero")
    return _refused(env, "view", "view: {root}/zero leads outside the repository {root} (through a symbolic link)", path="zero")


def view_not_utf8(env: SweEnvironment) -> tuple[bool, str]:
    _sh(env, "printf 'a\\377b\\n' > latin.txt")
    return _refused(env, "view", "view: {root}/latin.txt is not a UTF-8 text file", path="latin.txt")


def create_with_a_lone_surrogate(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(
        env,
        "create",
        "create: argument 'file_text' is not valid Unicode (it holds a lone surrogate)",
        path="s.py",
        file_text="x = '\udc80'\n",
    )


def a_command_too_long(env: SweEnvironment) -> tuple[bool, str]:
    command = "echo " + "x" * 200_000
    return _refused(
        env,
        "bash",
        f"bash: the command is {len(command)} bytes, over the 65536-byte limit; write a long script to a file with create, then run it",
        command=command,
    )


def a_command_with_a_nul_byte(env: SweEnvironment) -> tuple[bool, str]:
    return _refused(env, "bash", "bash: the command contains a NUL byte", command="echo a\x00b")


def loop_of_links(env: SweEnvironment) -> tuple[bool, str]:
    _sh(env, "ln -s loop2 loop1 && ln -s loop1 loop2")
    return _refused(env, "view", "view: {root}/loop1: too many levels of symbolic links", path="loop1")


# -- item 4: bounded reads --------------------------------------------------------------------


def view_two_lines_of_a_19mb_file(env: SweEnvironment) -> tuple[bool, str]:
    """View two lines of a 19 MB file: the worker's allocations grow by well under 1 MB."""
    _sh(env, f"seq 1 {BIG_LINES} > big.txt")
    size = int(_sh(env, "stat -c %s big.txt"))
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        obs, error, going = _call(env, "view", path="big.txt", view_range=[1000, 1001])
        grew = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    want = f"{env.workdir}/big.txt (lines 1000-1001 of {BIG_LINES}):\n  1000\t1000\n  1001\t1001"
    held = obs == want and error is None and going and grew < 1_000_000 and size > 19_000_000
    return held, f"file {size} bytes, allocations +{grew} bytes, {obs[:120]!r}"


def edit_a_19mb_file(env: SweEnvironment) -> tuple[bool, str]:
    """The editor reads a file whole: a 19 MB one is refused without being read."""
    _sh(env, f"test -e big.txt || seq 1 {BIG_LINES} > big.txt")
    size = int(_sh(env, "stat -c %s big.txt"))
    return _refused(
        env,
        "str_replace",
        f"str_replace: {{root}}/big.txt is {size} bytes, too large for the editor (at most 4000000 bytes); use bash",
        path="big.txt",
        old_str="1000\n",
        new_str="x\n",
    )


#: every attack through the tools, by name
TOOL_ATTACKS: dict[str, Attack] = {
    "symlink: view a link to /etc/passwd": view_link_to_a_container_file,
    "symlink: view through a linked folder": view_through_a_linked_folder,
    "symlink: list a linked folder": list_a_linked_folder,
    "symlink: create through a linked folder": create_through_a_linked_folder,
    "symlink: str_replace through a link": str_replace_through_a_link,
    "symlink: links copied as links": links_stay_links,
    "symlink: undo a create through a folder swapped for a link": undo_a_create_after_its_folder_became_a_link_out,
    "dangling link out: create": create_through_a_dangling_link_out,
    "dangling link in: create lands inside": create_through_a_dangling_link_in,
    "path with a NUL byte": path_with_a_nul_byte,
    "path of 6000 bytes": path_too_long,
    "view a fifo": view_a_fifo,
    "str_replace a fifo": edit_a_fifo,
    "view a device through a link": view_a_device_through_a_link,
    "view a non-UTF-8 file": view_not_utf8,
    "create with a lone surrogate": create_with_a_lone_surrogate,
    "bash command of 200 KB": a_command_too_long,
    "bash command with a NUL byte": a_command_with_a_nul_byte,
    "view a loop of links": loop_of_links,
    "view 2 lines of a 19 MB file": view_two_lines_of_a_19mb_file,
    "str_replace a 19 MB file": edit_a_19mb_file,
}


# -- item 3: every writable place bounded -----------------------------------------------------

#: the limits of the disk attack's sandbox (bytes): one bound per writable place
DISK_LIMIT = 20_000_000
SCRATCH_LIMIT = 20_000_000
#: what the command tries to write to each place: three files of 25 MB (one file alone is also
#: cut by ``ulimit -f`` at the disk limit; three overflow the place's own bound)
FILES, FILE_BYTES = 3, 25_000_000
PLACES = ("/tmp", "/var/tmp", "$HOME", ".")


def du_bytes(*paths: str) -> int | None:
    """``du -sbc`` of ``paths`` on this host (None when it cannot be read here)."""
    r = subprocess.run(["du", "-sbc", *paths], capture_output=True, text=True)
    try:
        return int(r.stdout.strip().splitlines()[-1].split()[0])
    except (IndexError, ValueError):
        return None


def _container_dirs(box: Sandbox) -> list[str]:
    """The host folders holding what the container writes: its writable layer and its own folder."""
    import docker

    c = docker.from_env().containers.get(getattr(box, "container_id", ""))
    return [c.attrs["GraphDriver"]["Data"]["UpperDir"], f"/var/lib/docker/containers/{c.id}"]


def disk_writes_to_every_place(folder: Path) -> dict[str, tuple[bool, str]]:
    """A command writes 75 MB to each of /tmp, /var/tmp, $HOME and the repository of a sandbox
    with a 20 MB bound each: every write stopped at its bound, and the container's folders under
    /var/lib/docker did not grow past the sum of the bounds (the growth of /var/lib/docker as a
    whole is told too: other work on the daemon moves it). One (held, detail) per place, and one
    for the host's disk."""
    repo = folder / "repo"
    repo.mkdir(parents=True)
    (repo / "a.txt").write_text("a\n")
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], cwd=repo, check=True)
    subprocess.run([*git, "add", "-A"], cwd=repo, check=True)
    subprocess.run([*git, "commit", "-qm", "a"], cwd=repo, check=True)
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, check=True, capture_output=True, text=True).stdout.strip()
    labels = {LABEL_RUN: f"chaos-disk-{uuid.uuid4().hex[:10]}"}
    limits = SandboxLimits(disk_bytes=DISK_LIMIT, scratch_bytes=SCRATCH_LIMIT, command_timeout_s=120)
    results: dict[str, tuple[bool, str]] = {}
    box: Sandbox | None = None
    try:
        box = open_sandbox("docker", SandboxSpec(str(repo), head, limits=limits, labels=labels))
        dirs = _container_dirs(box)
        before, whole_before = du_bytes(*dirs), du_bytes("/var/lib/docker")
        for place in PLACES:
            fill = "; ".join(f'head -c {FILE_BYTES} /dev/zero > "{place}/fill{i}.bin"' for i in range(FILES))
            r = box.run(f'{fill}; cat "{place}"/fill*.bin | wc -c')
            lines = r.output.strip().splitlines()
            written = int(lines[-1]) if lines and lines[-1].isdigit() else -1
            bound = -(-(DISK_LIMIT if place == "." else SCRATCH_LIMIT) // 4096) * 4096  # a tmpfs holds whole pages
            stopped = "No space left on device" in r.output
            held = stopped and 0 <= written <= bound
            results[f"disk: {FILES * FILE_BYTES // 1_000_000} MB to {place}"] = (
                held,
                f"{written} bytes kept (bound {bound}); {lines[0][:80] if lines else ''!r}",
            )
        after, whole_after = du_bytes(*dirs), du_bytes("/var/lib/docker")
        bound = DISK_LIMIT + 4 * SCRATCH_LIMIT
        grew = None if before is None or after is None else after - before
        whole = None if whole_before is None or whole_after is None else whole_after - whole_before
        results["disk: /var/lib/docker growth"] = (
            grew is not None and grew < bound,
            f"the container's folders grew {grew} bytes (bound {bound}); /var/lib/docker as a whole {whole} bytes",
        )
    finally:
        if box is not None:
            box.close()
        remove_labelled(labels)
    return results
