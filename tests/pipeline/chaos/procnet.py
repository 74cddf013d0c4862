"""Listening TCP sockets of a process tree, read from /proc (Linux; no psutil needed).

Why /proc: the check "every server the project starts listens on loopback only" must look at
what the kernel says is bound, for the driver and every Ray process it spawned, not at what a
configuration claims. A socket in LISTEN state (``0A``) is found in ``/proc/net/tcp{,6}`` by
inode; the inode is mapped to its process through the ``socket:[inode]`` links of
``/proc/<pid>/fd``.
"""

from __future__ import annotations

import ipaddress
import os
import socket
import struct
from dataclasses import dataclass

_LISTEN = "0A"


@dataclass(frozen=True, order=True)
class Listener:
    pid: int
    process: str
    host: str
    port: int

    @property
    def loopback(self) -> bool:
        addr = ipaddress.ip_address(self.host)
        if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is not None:
            addr = addr.ipv4_mapped
        return addr.is_loopback

    def __str__(self) -> str:
        return f"{self.process} (pid {self.pid}) on {self.host}:{self.port}"


def parse_address(hex_addr: str) -> tuple[str, int]:
    """``0100007F:1F90`` -> ('127.0.0.1', 8080); IPv6 words are little-endian per 32 bits."""
    ip_hex, port_hex = hex_addr.split(":")
    raw = bytes.fromhex(ip_hex)
    if len(raw) == 4:
        host = socket.inet_ntop(socket.AF_INET, struct.pack("<I", int(ip_hex, 16)))
    else:
        host = socket.inet_ntop(socket.AF_INET6, b"".join(raw[i : i + 4][::-1] for i in range(0, 16, 4)))
    return host, int(port_hex, 16)


def listening_inodes() -> dict[int, tuple[str, int]]:
    """inode -> (host, port) of every TCP socket in LISTEN state on this machine."""
    out: dict[int, tuple[str, int]] = {}
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            with open(table) as fh:
                lines = fh.read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            fields = line.split()
            if len(fields) > 9 and fields[3] == _LISTEN:
                out[int(fields[9])] = parse_address(fields[1])
    return out


def _ppid(pid: str) -> int | None:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return int(fh.read().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return None


def process_tree(root: int) -> list[int]:
    """``root`` and all its descendants (children, grandchildren...)."""
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            parent = _ppid(entry)
            if parent is not None:
                kids.setdefault(parent, []).append(int(entry))
    out, i = [root], 0
    while i < len(out):
        out += kids.get(out[i], [])
        i += 1
    return out


def command_of(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().split(b"\0")[0].decode(errors="replace")
    except OSError:
        return "?"


def listeners(pids: list[int]) -> list[Listener]:
    """Listening sockets held by any of ``pids``."""
    inodes = listening_inodes()
    found: set[Listener] = set()
    for pid in pids:
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                link = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if link.startswith("socket:["):
                inode = int(link[8:-1])
                if inode in inodes:
                    host, port = inodes[inode]
                    found.add(Listener(pid, command_of(pid).rsplit("/", 1)[-1][:40], host, port))
    return sorted(found)


def tree_processes(root: int, prefix: str) -> list[int]:
    """Descendants of ``root`` whose process title starts with ``prefix`` (Ray titles its
    actor processes ``ray::ClassName`` / ``ray::ClassName.method``)."""
    return [p for p in process_tree(root)[1:] if command_of(p).startswith(prefix)]
