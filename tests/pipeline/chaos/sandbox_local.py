"""The local sandbox against a model's escape, disk and symlink attacks (issue 35 items 1-4).

Each attack of :mod:`tests.workers.sandbox.local_attacks` (the same definitions the pytest tests
``tests/workers/sandbox/test_local_bwrap*.py`` assert) runs against a fresh local sandbox on a
tiny repository: ``umount /proc``, reading a host process's ``/proc/<pid>/environ``, ``nsenter``
into the host's network namespace, the host's loopback, ``mount``, ``chroot``, ptrace (strace,
gdb, ``ptrace(2)``) of a host pid, host files; writes past the disk limit to ``/tmp``,
``/var/tmp``, ``$HOME`` and the repository, and many small files; ``view``/``create`` through
symlinks leaving the repository; two lines of a 19 MB file read in bounded memory. One check each.
"""

from __future__ import annotations

import subprocess

from tests.pipeline.chaos.harness import Lab, ScenarioResult
from tests.workers.sandbox import local_attacks as A
from workers.sandbox import SandboxLimits, SandboxSpec, bwrap, open_sandbox
from workers.sandbox.local_sandbox import LocalSandbox


def _repo(lab: Lab) -> tuple[str, str]:
    p = lab.folder("sandbox-local-repo")
    run = lambda *a: subprocess.run(  # noqa: E731
        ["git", "-c", "user.name=t", "-c", "user.email=t@t", *a], cwd=p, check=True, capture_output=True, text=True
    ).stdout.strip()
    run("init", "-q")
    (p / "a.txt").write_text("hello\n")
    run("add", ".")
    run("commit", "-qm", "first")
    return str(p), run("rev-parse", "HEAD")


def sandbox_local(lab: Lab) -> ScenarioResult:
    res = ScenarioResult(f"local sandbox attacks ({len(A.ALL)})")
    res.begin_run()
    why = bwrap.probe()
    res.check("bubblewrap works here", why is None, why or "")
    path, commit = _repo(lab)
    held = 0
    with A.host_targets() as host:
        for name, attack in A.ALL.items():
            disk = SandboxLimits().disk_bytes if attack is A.view_two_lines_of_a_big_file else A.DISK_LIMIT
            spec = SandboxSpec(
                path, commit, limits=SandboxLimits(disk_bytes=disk), labels={"recap-eval.run": "chaos-sandbox-local"}
            )
            try:
                with open_sandbox("local", spec) as sb:
                    assert isinstance(sb, LocalSandbox)
                    ok, detail = attack(sb, host)
            except Exception as exc:  # noqa: BLE001 - an attack that breaks the sandbox did not hold
                ok, detail = False, f"{type(exc).__name__}: {exc}"
            held += ok
            res.check(name, ok, detail)
    res.notes.append(f"{held}/{len(A.ALL)} held")
    res.end_run()
    return res
