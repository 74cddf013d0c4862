"""The local sandbox's confinement: each command under bubblewrap (``bwrap``), probed once per process.

Why bubblewrap (issue 35 item 1): the former ``unshare --pid --mount-proc`` namespace left the
command root with every capability, so one ``umount /proc`` showed the host's processes (and
their environments) and ``nsenter --net=/proc/<pid>/ns/net`` reached the host's loopback. A
namespace the sandboxed process can leave is not isolation. bubblewrap is made for this (it is
what Flatpak runs applications in); each command runs as::

    bwrap --unshare-all [--share-net] --die-with-parent --new-session --cap-drop ALL
          --ro-bind /usr /usr  (and /etc, the PATH's other folders; /bin, /lib... as the host's symlinks)
          --proc /proc --dev /dev
          --bind <root>/repo <workdir>  --bind <root>/tmp /tmp  --bind <root>/vartmp /var/tmp
          --bind <root>/home <HOME>  --chdir <workdir> --clearenv --setenv ...  -- bash -c CMD

* every namespace is new (user, pid, mount, ipc, uts, cgroup, and the network unless the sweep
  turns it on): the host's processes do not exist in the command's ``/proc`` (a fresh procfs),
  so there is no host pid to ptrace, to ``nsenter`` or to read ``/proc/<pid>/environ`` of;
* every capability is dropped (bounding set included): ``mount``, ``umount``, ``chroot``,
  ``setns`` fail with EPERM whatever the uid inside says;
* the file system is built from nothing: the system's read-only folders (``/usr``, ``/etc``),
  and the only writable places are the sandbox's own folders (repository, ``/tmp``, ``/var/tmp``,
  ``$HOME``); the host's ``/root``, ``/home``, ``/work``, ``/tmp`` and every other folder are
  simply absent;
* ``--die-with-parent``: when the worker dies, the command dies (SIGKILL), and the pid
  namespace takes every process the command started with it.

The ``/bin`` -> ``usr/bin`` kind of top-level symlinks of a merged-usr system are recreated as
symlinks (``--symlink``), so the view is the host's own layout.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from functools import cache
from pathlib import Path

#: the host folders every command sees read-only (when they exist): programs, libraries, config
SYSTEM_DIRS = ("/usr", "/bin", "/sbin", "/lib", "/lib32", "/lib64", "/libx32", "/etc")
#: secrets under ``/etc`` hidden from the command (a root command inside owns root's files):
#: files read as an unreadable device, folders as an empty tmpfs
MASKED_FILES = ("/etc/shadow", "/etc/gshadow", "/etc/shadow-", "/etc/gshadow-", "/etc/sudoers", "/etc/.pwd.lock")
MASKED_DIRS = ("/etc/ssh", "/etc/ssl/private", "/etc/sudoers.d")


def bwrap_path() -> str | None:
    """The ``bwrap`` executable, or None."""
    return shutil.which("bwrap")


@cache
def probe() -> str | None:
    """Why bubblewrap cannot confine a command here (None: it can). Probed once per process:
    the exact flags a command gets, network off, a write to the read-only root refused."""
    exe = bwrap_path()
    if exe is None:
        return "bubblewrap (bwrap) is not installed"
    with tempfile.TemporaryDirectory(prefix="recap-bwrap-probe-") as d:
        argv = command_argv(
            "touch /usr/.recap-probe 2>/dev/null && exit 3; test -w /repo && echo ok",
            binds=system_binds(()),
            writable={"/repo": d},
            workdir="/repo",
            env={"PATH": "/usr/bin:/bin"},
            network=False,
        )
        try:
            r = subprocess.run(argv, capture_output=True, text=True, timeout=30)
        except (OSError, subprocess.TimeoutExpired) as exc:
            return f"bubblewrap does not run here ({exc})"
    if r.returncode != 0 or r.stdout.strip() != "ok":
        said = (r.stderr.strip().splitlines() or [f"exit {r.returncode}"])[-1]
        return f"bubblewrap does not work here ({said[:200]})"
    return None


def system_binds(path_dirs: Sequence[str]) -> list[str]:
    """bwrap arguments for the read-only system folders and the PATH's folders outside them
    (a virtual environment's folder whole, so its ``lib`` comes with its ``bin``)."""
    out: list[str] = []
    bound: list[str] = []
    for d in SYSTEM_DIRS:
        if os.path.islink(d):
            out += ["--symlink", os.readlink(d), d]
        elif os.path.isdir(d):
            out += ["--ro-bind", d, d]
            bound.append(d)
    out += [x for f in MASKED_FILES if os.path.isfile(f) for x in ("--ro-bind", "/dev/null", f)]
    out += [x for d in MASKED_DIRS if os.path.isdir(d) and not os.path.islink(d) for x in ("--tmpfs", d)]
    for d in path_dirs:
        if not d.startswith("/") or not os.path.isdir(d):
            continue
        src = tool_prefix(os.path.realpath(d))
        if any(src == b or src.startswith(b + "/") for b in bound) or src in ("/", "/root", "/home", "/tmp"):
            continue
        out += ["--ro-bind", src, src]
        bound.append(src)
    return out


#: a folder holding one of these is a tool's whole installation (its ``bin`` needs the rest):
#: a virtual environment, pyenv (its shims call ``libexec/pyenv``), conda
PREFIX_MARKS = ("pyvenv.cfg", "libexec/pyenv", "conda-meta")


def tool_prefix(path_dir: str) -> str:
    """The folder to bind for a PATH folder: the installation it belongs to (up to three
    levels up, by :data:`PREFIX_MARKS`), else the folder itself."""
    here = path_dir
    for _ in range(4):
        if any(os.path.exists(os.path.join(here, m)) for m in PREFIX_MARKS):
            return here
        here = os.path.dirname(here)
    return path_dir


def command_argv(
    command: str,
    *,
    binds: Sequence[str],
    writable: Mapping[str, str | Path],
    workdir: str,
    env: Mapping[str, str],
    network: bool,
) -> list[str]:
    """The argv running ``bash -c command`` under bubblewrap: ``writable`` maps each path inside
    to its host folder (the only read-write binds), ``env`` is the whole environment."""
    exe = bwrap_path() or "bwrap"
    argv = [exe, "--unshare-all"]
    if network:
        argv.append("--share-net")
    argv += ["--die-with-parent", "--new-session", "--cap-drop", "ALL", *binds, "--proc", "/proc", "--dev", "/dev"]
    for inside, host in writable.items():
        argv += ["--bind", str(host), inside]
    argv += ["--chdir", workdir, "--clearenv"]
    for k, v in env.items():
        argv += ["--setenv", k, v]
    return [*argv, "--", "bash", "-c", command]
