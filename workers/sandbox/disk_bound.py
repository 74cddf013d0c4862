"""The local sandbox's disk bound: all its writable places on one size-limited tmpfs, or a watchdog.

Why (issue 35 item 3): ``disk_bytes`` watched only the repository folder, so a command wrote
46 MB to the host's ``$TMPDIR`` past a 20 MB limit. Every place a local sandbox's command can
write (the repository, ``/tmp``, ``/var/tmp``, ``$HOME``) is a folder under the sandbox's one
temporary root, and that root is bounded as a whole:

* where the worker may mount (root with CAP_SYS_ADMIN, as in the project's containers), the
  root *is* a tmpfs mounted with ``size=`` (the disk limit plus a little headroom, so a command
  that goes past the limit is caught and reported, and one that keeps writing gets ENOSPC) and
  ``nr_inodes=`` (so a million empty files stop too: tmpfs charges no data page for an empty
  file). It lives as long as the sandbox (the repository persists across commands, which a
  per-command ``bwrap --size`` tmpfs would not), and the kernel enforces it at the write;
  its pages are memory (swappable), taken only as files are written;
* elsewhere, a watchdog measures the root (bytes and entries) four times a second while a
  command runs and kills the command when it is over; ``RLIMIT_FSIZE`` caps any single file at
  what was left of the limit when the command started. A reactive bound: what a command writes
  in many files between two looks gets through before it is stopped (and reported).

bubblewrap's own ``--size`` tmpfs is not used for ``/tmp``: the shell session's state file lives
in ``$TMPDIR`` and must outlive the command (:mod:`workers.sandbox.session`).
"""

from __future__ import annotations

import os
import subprocess
import tempfile
from functools import cache
from pathlib import Path

#: bytes over the limit the tmpfs still takes, so an overrun is measured and reported (not
#: only an ENOSPC the command may swallow)
HEADROOM_MAX = 16 << 20


def tmpfs_size(disk_bytes: int) -> int:
    """The tmpfs's size for a ``disk_bytes`` limit: the limit plus 1/8 of it (at most 16 MiB)."""
    return disk_bytes + min(HEADROOM_MAX, max(disk_bytes // 8, 64 << 10))


def tmpfs_inodes(disk_bytes: int) -> int:
    """Files and folders the tmpfs may hold: one per 4 KiB of the limit, at least 4096."""
    return max(disk_bytes // 4096, 4096)


@cache
def can_mount() -> bool:
    """Whether this process can mount a tmpfs (probed once: a 64 KiB one, unmounted at once)."""
    if os.geteuid() != 0:
        return False
    with tempfile.TemporaryDirectory(prefix="recap-mount-probe-") as d:
        if not mount_tmpfs(Path(d), 64 << 10, 64):
            return False
        unmount(Path(d))
    return True


def mount_tmpfs(path: Path, size: int, inodes: int) -> bool:
    """Mount a tmpfs of ``size`` bytes and ``inodes`` entries on ``path`` (mode 0700); whether it worked."""
    try:
        r = subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={size},nr_inodes={inodes},mode=0700", "recap-sandbox", str(path)],
            capture_output=True,
            timeout=30,
        )
    except (OSError, subprocess.TimeoutExpired):
        return False
    return r.returncode == 0


def unmount(path: Path) -> None:
    """Unmount ``path`` if something is mounted there (lazily when busy); no error otherwise."""
    if not os.path.ismount(path):
        return
    for args in (["umount", str(path)], ["umount", "-l", str(path)]):
        try:
            if subprocess.run(args, capture_output=True, timeout=30).returncode == 0:
                return
        except (OSError, subprocess.TimeoutExpired):
            continue


def tree_usage(root: Path) -> tuple[int, int]:
    """(bytes of the regular files, entries) under ``root``, links not followed."""
    total = n = 0
    for dirpath, dirs, files in os.walk(root):
        n += len(dirs) + len(files)
        for name in files:
            try:
                total += os.lstat(os.path.join(dirpath, name)).st_size
            except OSError:
                pass
    return total, n


def used_bytes(root: Path, mounted: bool) -> int:
    """What the sandbox's files take: the tmpfs's used blocks when it is one, else the sum of
    the file sizes under ``root``."""
    if mounted:
        st = os.statvfs(root)
        return (st.f_blocks - st.f_bfree) * st.f_frsize
    return tree_usage(root)[0]
