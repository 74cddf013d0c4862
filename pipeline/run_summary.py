"""What one driver session did, and the exit status it turns into.

Exit status of ``run``/``resume`` (the CLI adds 2 for bad input, a folder in use or a sink that
stayed dead): 0 when every unit of the plan is done, 3 when work remains, 4 when a unit ended
in an infrastructure failure, 130 when interrupted with work left (see :mod:`pipeline.driver`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from recap.plural import count

#: exit status of a session in which a unit ended in an infrastructure failure
EXIT_INFRA = 4
#: exit status of a session that left work undone (a cap stopped it)
EXIT_WORK_REMAINS = 3
#: exit status of a session stopped by Ctrl-C / SIGTERM with work left
EXIT_INTERRUPTED = 130


@dataclass
class RunSummary:
    """What one driver session did (counts are for this session unless named ``*_before``); the CLI prints it and
    turns it into the exit status."""

    location: str
    run: str
    run_id: str
    total: int
    completed_before: int
    finished_now: int = 0
    success_now: int = 0
    budget_stopped: int = 0
    abandoned: int = 0
    not_started: int = 0
    worker_restarts: int = 0
    spend_usd: float = 0.0
    stopped: str | None = None
    interrupted: bool = False
    wall_s: float = 0.0
    #: units that ended this session in an infrastructure failure (retryable), by failure kind
    infra_failed: int = 0
    infra_kinds: dict[str, int] = field(default_factory=dict)
    #: rows the sink had logged but not written when a session began (a crash), now written
    recovered_rows: int = 0
    #: units queued again because their latest completing row ended env_error / llm_error
    #: (``retry="errors"``, ``recap resume RUN --retry errors``)
    retried_errors: int = 0
    #: attempts in flight when the session was stopped (cut by a second Ctrl-C or the end of
    #: the grace period; 0 after a graceful stop that let them finish)
    cut: int = 0

    @property
    def all_done(self) -> bool:
        """True when every unit of the plan has a finished row, this session or an earlier one."""
        return self.completed_before + self.finished_now >= self.total

    def retry_hint(self) -> str | None:
        """One line on the units to retry, or None."""
        if not self.infra_failed:
            return None
        kinds = ", ".join(f"{k} {n}" for k, n in sorted(self.infra_kinds.items()))
        return (
            f"{count(self.infra_failed, 'unit')} ended in an infrastructure failure ({kinds}); fix the cause, "
            f"then retry them with: recap resume {self.location}"
        )

    def exit_code(self) -> int:
        """The process exit status: interrupted beats an infrastructure failure, which beats work left (a cap
        stopped it); 0 only when all is done."""
        if self.interrupted:
            return EXIT_INTERRUPTED
        if self.infra_failed:
            return EXIT_INFRA
        return 0 if self.all_done else EXIT_WORK_REMAINS
