"""Chaos: a model's attacks on a docker sandbox through the coding tools (issue 35 items 2-5).

Every attack of :mod:`tests.workers.envs.swe.hostile_tools` (the same functions its pytest test,
``tests/workers/envs/swe/test_hostile_tools.py``, asserts one by one), one check each: symlink
escapes for ``view``, ``create`` and ``str_replace``; links copied as links; ``create`` through
dangling links; paths with a NUL byte, too long, a fifo, a device, a loop of links; text that is
not Unicode; commands too long; a view of two lines of a 19 MB file (the worker's allocations);
a file too large for the editor; and writes past the bound of /tmp, /var/tmp, $HOME and the
repository (with the growth of /var/lib/docker). Held: refused or bounded, the episode going on.
"""

from __future__ import annotations

import uuid

from tests.pipeline.chaos.harness import Lab, ScenarioResult
from tests.workers.envs.swe import hostile_tools as H
from workers.sandbox import LABEL_RUN, remove_labelled


def sandbox_docker(lab: Lab) -> ScenarioResult:
    res = ScenarioResult(f"docker sandbox attacks ({len(H.TOOL_ATTACKS)} tool calls + {len(H.PLACES) + 1} disk)")
    res.begin_run()
    tasks = H.hostile_repo(lab.folder("sandbox-docker") / "tasks")
    labels = {LABEL_RUN: f"chaos-{uuid.uuid4().hex[:12]}"}
    tried = held = 0
    env = H.docker_env(tasks, labels, max_commands=500)
    try:
        for name, attack in H.TOOL_ATTACKS.items():
            try:
                ok, detail = attack(env)
            except Exception as exc:  # a raise is what the attack looks for: the episode would end
                ok, detail = False, f"raised {type(exc).__name__}: {exc}"[:300]
            tried, held = tried + 1, held + ok
            res.check(name, ok, detail)
    finally:
        env.close()
        remove_labelled(labels)
    for name, (ok, detail) in H.disk_writes_to_every_place(lab.folder("sandbox-docker") / "disk").items():
        tried, held = tried + 1, held + ok
        res.check(name, ok, detail)
    res.notes.append(f"{held}/{tried} held")
    res.end_run()
    return res
