"""How ``recap sql`` names the death of its query process (reports/sandbox.py): a child that dies
of a signal while its address space is at the cap the memory limit set (an allocation failing in
native code: seen under load as a SIGSEGV of a cross join) hit the memory limit and is told so; a
child that dies of the same signal far from its cap crashed, and is told that."""

from __future__ import annotations

import io
import os
import subprocess
import sys

from reports import sandbox

#: a stand-in for the query process: caps its address space 64 MB above what it has, says so the
#: way child_main does, fills the room when asked, then dies of SIGSEGV
CHILD = r"""
import os, resource, signal, struct, sys, time
fd, grow = int(sys.argv[1]), sys.argv[2] == "grow"
page = os.sysconf("SC_PAGE_SIZE")
size = int(open("/proc/self/statm").read().split()[0]) * page
cap = size + (64 << 20)
resource.setrlimit(resource.RLIMIT_AS, (cap, resource.getrlimit(resource.RLIMIT_AS)[1]))
os.write(fd, struct.pack("<cQQ", b"R", size, cap))
held = []
if grow:
    try:
        while True:
            held.append(bytearray(1 << 20))
    except MemoryError:
        pass
time.sleep(0.3)  # a few of the parent's looks at the address space
os.kill(os.getpid(), signal.SIGSEGV)
"""


def _told(mode: str) -> tuple[str | None, str]:
    r, w = os.pipe()
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(w), mode], pass_fds=(w,))
    os.close(w)
    os.set_blocking(r, False)
    watch = sandbox._Watch(proc, r, sandbox.Limits(memory_bytes=4 * 1000**3, timeout_s=60, memory_text="4GB"))
    try:
        watch.until_exit()
    finally:
        os.close(r)
    err = io.StringIO()
    sandbox._say_limit(watch, err)
    return watch.limit_hit, err.getvalue()


def test_a_child_dying_at_its_address_space_cap_hit_the_memory_limit():
    hit, line = _told("grow")
    assert hit == "address space"
    assert line.startswith("recap: error: sql: memory limit 4GB hit: the query process died (SIGSEGV) at its address-space cap (")
    assert line.endswith(" mapped); raise it with --memory-limit, or select fewer rows or smaller values\n")


def test_a_child_dying_far_from_its_cap_crashed():
    assert _told("idle") == (None, "recap: error: sql: the query process died (SIGSEGV); try a smaller query\n")
