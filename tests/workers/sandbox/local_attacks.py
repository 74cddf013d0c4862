"""Attacks on a local sandbox (issue 35 items 1-4), one function each: the pytest tests
(test_local_bwrap*.py) and the chaos lab's ``sandbox_local`` scenario run the same definitions.

Each attack gets an open :class:`~workers.sandbox.local_sandbox.LocalSandbox` and a :class:`Host`
(a host process holding a secret in its environment, a service on the host's loopback, a secret
file on the host) and returns ``(held, detail)``: whether the sandbox held, and what was seen.
"""

from __future__ import annotations

import os
import socket
import subprocess
import tempfile
import threading
import tracemalloc
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from workers.sandbox import disk_bound
from workers.sandbox.base import OutsideRepository
from workers.sandbox.local_sandbox import LocalSandbox

#: the disk limit the disk attacks run under; each writes four files of 90 % of it (no single
#: file over the limit, so ``RLIMIT_FSIZE`` alone does not stop them)
DISK_LIMIT = 4_000_000
FILE = DISK_LIMIT * 9 // 10


@dataclass
class Host:
    """What the attacks aim at on the host."""

    pid: int  # a host process with GATEWAY_API_KEY=secret in its environment
    secret: str
    port: int  # a TCP service on the host's 127.0.0.1
    secret_file: Path  # a host file outside the repository, holding the secret
    outside_dir: Path  # a host folder a symlink may point at


@contextmanager
def host_targets() -> Iterator[Host]:
    """A host process with a secret in its environment, a loopback service, a secret file."""
    secret = f"secret-{uuid.uuid4().hex}"
    proc = subprocess.Popen(["sleep", "600"], env={"PATH": os.environ.get("PATH", "/usr/bin:/bin"), "GATEWAY_API_KEY": secret})
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    stop = threading.Event()

    def serve() -> None:
        srv.settimeout(0.2)
        while not stop.is_set():
            try:
                c, _ = srv.accept()
                c.sendall(b"HOST-SERVICE\n")
                c.close()
            except OSError:
                continue

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    with tempfile.TemporaryDirectory(prefix="recap-attack-host-") as d:
        secret_file = Path(d) / "secret.txt"
        secret_file.write_text(secret + "\n")
        outside = Path(d) / "outside"
        outside.mkdir()
        try:
            yield Host(proc.pid, secret, srv.getsockname()[1], secret_file, outside)
        finally:
            stop.set()
            t.join(timeout=2)
            srv.close()
            proc.kill()
            proc.wait()


Attack = Callable[[LocalSandbox, Host], tuple[bool, str]]


def _out(sb: LocalSandbox, cmd: str) -> str:
    r = sb.run(cmd, timeout_s=20)
    return r.output.strip()


# -- item 1: escapes ----------------------------------------------------------------------------


def umount_proc(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(sb, f"umount /proc 2>&1; echo rc=$?; ls /proc | grep -cx {host.pid}; cat /proc/{host.pid}/environ 2>&1")
    held = "rc=0" not in out and host.secret not in out
    return held, out.splitlines()[0][:120] if out else ""


def read_host_environ(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(sb, f"cat /proc/{host.pid}/environ 2>&1; cat /proc/[0-9]*/environ 2>/dev/null | tr '\\0' '\\n' | grep GATEWAY")
    return host.secret not in out, out[:120]


def nsenter_host_net(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(
        sb,
        f"nsenter --net=/proc/{host.pid}/ns/net bash -c 'exec 3<>/dev/tcp/127.0.0.1/{host.port} && head -1 <&3' 2>&1; "
        f"nsenter -t {host.pid} -n true 2>&1; echo rc=$?",
    )
    return "HOST-SERVICE" not in out and "rc=0" not in out, out.replace("\n", " | ")[:160]


def host_loopback(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(sb, f"bash -c 'exec 3<>/dev/tcp/127.0.0.1/{host.port} && head -1 <&3' 2>&1; echo rc=$?")
    return "HOST-SERVICE" not in out, out.replace("\n", " | ")[:120]


def mount_tmpfs(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(sb, "mount -t tmpfs none /tmp 2>&1; echo rc=$?; mount --bind / /tmp 2>&1; echo rc=$?")
    return "rc=0" not in out, out.replace("\n", " | ")[:120]


def chroot_out(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(sb, "/usr/sbin/chroot / true 2>&1; echo rc=$?")
    return "rc=0" not in out, out.replace("\n", " | ")[:120]


def ptrace_host(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    tools = [
        f"timeout 5 strace -p {host.pid} -e trace=none 2>&1; echo strace=$?",
        f"timeout 10 gdb -p {host.pid} -batch -ex 'info proc' 2>&1 | tail -2; echo gdb=${{PIPESTATUS[0]}}",
        f"python3 -c 'import ctypes,sys; print(\"ptrace\", ctypes.CDLL(None).ptrace(16, {host.pid}, 0, 0))' 2>&1",
    ]
    out = _out(sb, "; ".join(tools))
    attached = "strace=0" in out or "ptrace 0" in out or "process " + str(host.pid) in out
    return not attached, out.replace("\n", " | ")[:160]


def host_files(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    out = _out(
        sb,
        f"cat {host.secret_file} 2>&1; touch /usr/.recap-attack /etc/.recap-attack 2>&1; echo rc=$?; "
        "head -c 64 /etc/shadow 2>&1 | grep -c '^root:'",
    )
    held = host.secret not in out and "rc=0" not in out and not Path("/usr/.recap-attack").exists()
    held = held and out.endswith("\n0")  # the host's /etc/shadow is not readable
    return held, out.replace("\n", " | ")[:160]


ESCAPES: dict[str, Attack] = {
    "umount /proc": umount_proc,
    "read a host process's environ": read_host_environ,
    "nsenter into the host's net ns": nsenter_host_net,
    "host loopback service": host_loopback,
    "mount": mount_tmpfs,
    "chroot": chroot_out,
    "ptrace/strace/gdb of a host pid": ptrace_host,
    "read a host file or /etc/shadow, write the system": host_files,
}


# -- item 3: disk ------------------------------------------------------------------------------


def _bounded(sb: LocalSandbox, where: str, cmd: str) -> tuple[bool, str]:
    """Run a write past the limit; held when it failed (ENOSPC/EFBIG) or was stopped and
    reported, and the sandbox's root (every writable place) stayed within its bound."""
    r = sb.run(cmd, timeout_s=60)
    used = disk_bound.tree_usage(sb.root)[0]
    bound = disk_bound.tmpfs_size(sb.limits.disk_bytes)
    said = "No space left" in r.output or "File too large" in r.output or (r.exit_code is None and "disk limit]" in r.output)
    held = said and used <= bound
    sb.run(f"rm -rf {where}/recap-big*", timeout_s=60)
    return (
        held,
        f"{r.output.strip().splitlines()[-1][:100] if r.output.strip() else ''} (root {used} <= {bound}: {used <= bound})",
    )


def write_command(place: str) -> str:
    """The shell command writing four files of 90 % of the limit to ``place``."""
    where = {"$HOME": '"$HOME"', "repo": "."}.get(place, place)
    return f"for i in 1 2 3 4; do head -c {FILE} /dev/zero > {where}/recap-big$i || break; done 2>&1; echo rc=$?"


def _write_to(place: str) -> Attack:
    def attack(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
        where = {"$HOME": '"$HOME"', "repo": "."}.get(place, place)
        return _bounded(sb, where, write_command(place))

    return attack


def small_files_command(disk_bytes: int) -> tuple[int, str]:
    """How many empty files, and the command creating them in ``/tmp``: four times the entries
    a tmpfs of the limit holds."""
    n = disk_bound.tmpfs_inodes(disk_bytes) * 4
    return n, f"mkdir -p /tmp/recap-big; cd /tmp/recap-big; for i in $(seq {n}); do : > f$i || break; done 2>&1 | tail -1"


def many_small_files(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    n, cmd = small_files_command(sb.limits.disk_bytes)
    r = sb.run(cmd, timeout_s=120)
    entries = disk_bound.tree_usage(sb.root)[1]
    sb.run("rm -rf /tmp/recap-big", timeout_s=60)
    held = entries < n and ("No space left" in r.output or (r.exit_code is None and "disk limit]" in r.output))
    return held, f"{entries} entries of {n} tried: {r.output.strip()[-80:]}"


DISK: dict[str, Attack] = {
    "write past the limit to /tmp": _write_to("/tmp"),
    "write past the limit to /var/tmp": _write_to("/var/tmp"),
    "write past the limit to $HOME": _write_to("$HOME"),
    "write past the limit to the repository": _write_to("repo"),
    "many small files": many_small_files,
}


# -- item 2: symlinks ----------------------------------------------------------------------------


def _refused(op: Callable[[], object]) -> tuple[bool, str]:
    try:
        op()
    except OutsideRepository as exc:
        return True, f"refused: {exc}"[:140]
    except Exception as exc:  # noqa: BLE001 - any other failure is not the promised refusal
        return False, f"{type(exc).__name__}: {exc}"[:140]
    return False, "the operation went through"


def view_symlink_to_host_file(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    sb.run(f"ln -sf {host.secret_file} leak.txt; ln -sf /etc/passwd passwd.txt")
    a = _refused(lambda: sb.read_file("leak.txt"))
    b = _refused(lambda: sb.read_lines("passwd.txt", 1, 2, 1000))
    return a[0] and b[0], a[1]


def view_symlink_up(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    sb.run("mkdir -p sub && ln -sf ../.. sub/up")
    return _refused(lambda: sb.read_file("sub/up/etc/passwd"))


def create_through_symlinked_folder(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    sb.run(f"ln -sfn {host.outside_dir} hostdir")
    held, detail = _refused(lambda: sb.write_file("hostdir/planted.txt", b"x"))
    return held and not (host.outside_dir / "planted.txt").exists(), detail


def create_through_dangling_symlink(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    target = host.outside_dir / "dangling-target.txt"
    sb.run(f"ln -sf {target} dangling.txt")
    held, detail = _refused(lambda: sb.write_file("dangling.txt", b"x"))
    return held and not target.exists(), detail


SYMLINKS: dict[str, Attack] = {
    "view a symlink to a host file": view_symlink_to_host_file,
    "view through a symlink to ../..": view_symlink_up,
    "create through a symlinked folder": create_through_symlinked_folder,
    "create through a dangling symlink": create_through_dangling_symlink,
}


# -- item 4: the worker's memory ------------------------------------------------------------------


def view_two_lines_of_a_big_file(sb: LocalSandbox, host: Host) -> tuple[bool, str]:
    """Two lines of a 19 MB file: the worker allocates well under 1 MB (tracemalloc's peak)."""
    sb.run("yes \"$(printf '%099d' 0 | tr 0 x)\" | head -n 190000 > big.txt")  # 100-byte lines: 19 MB
    tracemalloc.start()
    try:
        got = sb.read_lines("big.txt", 5, 6, 10_000)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    ok = got.data == (b"x" * 99 + b"\n") * 2 and got.total_lines == 190000 and got.total_bytes == 19_000_000
    return ok and peak < 1 << 20, f"peak {peak} bytes, {got.total_lines} lines, {got.total_bytes} bytes"


ALL: dict[str, Attack] = {**ESCAPES, **DISK, **SYMLINKS, "view 2 lines of a 19 MB file": view_two_lines_of_a_big_file}
