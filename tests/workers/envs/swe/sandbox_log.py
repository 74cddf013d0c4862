"""The sandboxes the environment tests open: real local sandboxes (:mod:`workers.sandbox`), kept
so a test can see how many were opened and that each was closed."""

from __future__ import annotations

from workers.sandbox import Sandbox, SandboxSpec, open_sandbox


class SandboxLog:
    """A ``SandboxSpec -> Sandbox`` factory opening local sandboxes and keeping each."""

    def __init__(self) -> None:
        self.opened: list[Sandbox] = []
        self.specs: list[SandboxSpec] = []

    def __call__(self, spec: SandboxSpec) -> Sandbox:
        box = open_sandbox("local", spec)
        self.opened.append(box)
        self.specs.append(spec)
        return box
