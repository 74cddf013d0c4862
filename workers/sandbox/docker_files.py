"""File operations of the docker sandbox, done *inside* the container by one small bash script.

Why inside, and not with the daemon's archive calls (``get_archive``/``put_archive``): the archive
calls resolve a path in the container's whole filesystem, so a committed link to ``/etc/passwd``
or a folder linked to ``/`` is followed out of the repository (issue 35 item 2); they read a
whole file into the worker to show two lines of it (item 4); they cannot write into a tmpfs
mount, nor anywhere under a read-only root filesystem (item 3); and a write through a dangling
link fails with a daemon error 500 (item 5). The script resolves the path with ``realpath -m``
(every component, the last included: a dangling link is resolved to the place a write would
create), refuses it unless it stays in the repository, then reads, counts or writes the
*resolved* path, which holds no link (no model command runs while a tool's file operation runs,
so nothing can swap a link in between). It needs bash and coreutils (``realpath``, ``stat``,
``head``, ``sed``, ``wc``) only: our image and the SWE-bench harness's images have them.

Reads come back on the exec's stdout, bounded in the container (``head -c``); writes go in on the
exec's stdin (the attach socket, half-closed at the end), so no size limit of a command line
applies and nothing is staged outside the repository. A failure is an exit status of the
script; :func:`raise_for` turns it into the exception the OS would raise (or
:class:`~workers.sandbox.base.OutsideRepository`, :class:`~workers.sandbox.base.FileTooLarge`).
"""

from __future__ import annotations

import errno
import socket
import struct
import time
from typing import Any

from workers.sandbox.base import FileSlice, FileTooLarge, OutsideRepository

#: a path longer than this (bytes) is refused before anything runs (Linux's PATH_MAX)
PATH_MAX = 4096

#: exit statuses of :data:`FILE_OP` (errno values where one fits)
NOT_FOUND, NOT_A_DIR, IS_A_DIR, TOO_BIG, LOOP = 2, 20, 21, 27, 40
NO_REPO, OUTSIDE, NOT_REGULAR, WRITE_FAILED = 90, 92, 93, 94

FILE_OP = r"""
op=$1 root=$2 path=$3
root=$(realpath -e -- "$root" 2>/dev/null) || exit 90
cd -- "$root" || exit 90
r=$(realpath -m -- "$path" 2>/dev/null) || exit 40
case "$r" in "$root"|"$root"/*) ;; *) printf '%s' "$r"; exit 92 ;; esac
[ -L "$r" ] && exit 40
case "$op" in
read)
  max=$4
  [ -e "$r" ] || exit 2
  [ -d "$r" ] && exit 21
  [ -f "$r" ] || exit 93
  size=$(stat -c %s -- "$r") || exit 2
  if [ "$max" -ge 0 ] && [ "$size" -gt "$max" ]; then printf '%s' "$size"; exit 27; fi
  printf '%s\n' "$size"
  exec head -c "$size" -- "$r"
  ;;
lines)
  first=$4 last=$5 max=$6
  [ -e "$r" ] || exit 2
  [ -d "$r" ] && exit 21
  [ -f "$r" ] || exit 93
  size=$(stat -c %s -- "$r") || exit 2
  n=$(wc -l < "$r") || exit 2
  if [ "$size" -gt 0 ] && [ "$(tail -c 1 -- "$r" | wc -l)" -eq 0 ]; then n=$((n + 1)); fi
  printf '%s %s\n' "$n" "$size"
  if [ "$last" -gt 0 ]; then sed -n "${first},${last}p;${last}q" -- "$r"; else sed -n "${first},\$p" -- "$r"; fi | head -c $((max + 1))
  exit 0
  ;;
write)
  [ -d "$r" ] && exit 21
  if [ -e "$r" ] && [ ! -f "$r" ]; then exit 93; fi
  d=${r%/*}
  [ -n "$d" ] || d=/
  if [ ! -d "$d" ]; then
    [ -e "$d" ] && exit 20
    mkdir -p -- "$d" 2>/dev/null || exit 20
  fi
  cat > "$r" || exit 94
  exit 0
  ;;
esac
exit 99
"""


def check_path(path: str) -> None:
    """Refuse, as the OS would, a path no file operation can take: a NUL byte (ValueError, as
    Python's own ``open`` raises), too long (ENAMETOOLONG), not encodable."""
    if "\x00" in path:
        raise ValueError("embedded null byte")
    try:
        size = len(path.encode("utf-8"))
    except UnicodeEncodeError:
        raise ValueError("the path is not valid Unicode") from None
    if size > PATH_MAX:
        raise OSError(errno.ENAMETOOLONG, "File name too long", path[:80] + "...")


def raise_for(code: int, out: bytes, path: str, *, max_bytes: int | None = None) -> None:
    """Raise what the script's exit status ``code`` says (nothing for 0)."""
    if code == 0:
        return
    if code == OUTSIDE:
        where = out.decode("utf-8", errors="replace")[:300]
        raise OutsideRepository(errno.EACCES, f"resolves to {where}, outside the repository", path)
    if code == NOT_FOUND or code == NO_REPO:
        raise FileNotFoundError(errno.ENOENT, "No such file or directory", path)
    if code == IS_A_DIR:
        raise IsADirectoryError(errno.EISDIR, "Is a directory", path)
    if code == NOT_A_DIR:
        raise NotADirectoryError(errno.ENOTDIR, "Not a directory", path)
    if code == LOOP:
        raise OSError(errno.ELOOP, "Too many levels of symbolic links", path)
    if code == TOO_BIG:
        raise FileTooLarge(path, int(out.strip() or b"0"), max_bytes if max_bytes is not None else -1)
    if code == NOT_REGULAR:
        raise OSError(errno.EINVAL, "Not a regular file", path)
    if code == WRITE_FAILED:
        raise OSError(errno.EIO, "The file could not be written (no space left, or not writable)", path)
    raise OSError(errno.EIO, f"the sandbox's file operation failed (exit {code}): {out[-200:].decode(errors='replace')}", path)


def parse_read(out: bytes, path: str) -> bytes:
    """The file's bytes from a ``read``'s output (its size line, then the bytes)."""
    head, _, data = out.partition(b"\n")
    if not head.isdigit():
        raise OSError(errno.EIO, "the sandbox's read gave no size", path)
    return data


def parse_lines(out: bytes, path: str, max_bytes: int) -> FileSlice:
    """The :class:`FileSlice` from a ``lines``' output (``<lines> <bytes>``, then at most
    ``max_bytes + 1`` bytes of the lines: one more than allowed says the slice was cut)."""
    head, _, data = out.partition(b"\n")
    fields = head.split()
    if len(fields) != 2 or not all(f.isdigit() for f in fields):
        raise OSError(errno.EIO, "the sandbox's line count is missing", path)
    cut = len(data) > max_bytes
    return FileSlice(data[:max_bytes], int(fields[0]), int(fields[1]), cut)


def exec_with_stdin(api: Any, container_id: str, argv: list[str], data: bytes, timeout_s: float = 120.0) -> tuple[int, bytes]:
    """Run ``argv`` in the container with ``data`` on its stdin; (exit status, stdout).

    Through the exec's attach socket (``exec_start(socket=True)``), half-closed after ``data`` so
    the command sees the end of its input, as ``docker exec -i`` does."""
    exec_id = api.exec_create(container_id, argv, stdin=True, stdout=True, stderr=False)["Id"]
    sock = api.exec_start(exec_id, socket=True)
    raw = getattr(sock, "_sock", sock)
    try:
        raw.settimeout(timeout_s)
        view = memoryview(data)
        for at in range(0, len(view), 1 << 16):
            raw.sendall(view[at : at + (1 << 16)])
        raw.shutdown(socket.SHUT_WR)
        out = _read_frames(raw)
    finally:
        sock.close()
    for _ in range(200):
        info = api.exec_inspect(exec_id)
        if not info.get("Running"):
            code = info.get("ExitCode")
            return (int(code) if code is not None else -1), out
        time.sleep(0.02)
    return -1, out


def _read_frames(raw: Any) -> bytes:
    """The stdout of a multiplexed attach stream (8-byte frame headers: stream, 0, 0, 0, size)."""
    buf = bytearray()
    while True:
        chunk = raw.recv(1 << 16)
        if not chunk:
            break
        buf += chunk
    out = bytearray()
    at = 0
    while at + 8 <= len(buf):
        stream, size = buf[at], struct.unpack(">I", buf[at + 4 : at + 8])[0]
        if stream == 1:
            out += buf[at + 8 : at + 8 + size]
        at += 8 + size
    return bytes(out)
