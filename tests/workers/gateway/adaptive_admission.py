"""An admission controller with an adaptive in-flight limit on a test clock (no RPM/TPM): what the
adaptive-limit and queue-feed tests drive call by call."""

from __future__ import annotations

from workers.gateway.adaptive import AdaptiveLimit, LimitChange
from workers.gateway.limits import AdmissionController


def adaptive_controller(now: list[float], changes: list[LimitChange], *, floor: int, ceiling: int) -> AdmissionController:
    """``ceiling`` calls in flight at first, never fewer than ``floor``; ``now[0]`` is the clock and
    every limit change is appended to ``changes``."""
    return AdmissionController(
        rpm=None,
        tpm=None,
        window_s=60.0,
        pad_s=0.0,
        max_concurrency=ceiling,
        clock=lambda: now[0],
        adaptive=AdaptiveLimit(floor=floor, ceiling=ceiling),
        on_limit=changes.append,
    )
