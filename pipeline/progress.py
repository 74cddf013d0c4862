"""Live progress of a sweep: units done/total, success so far, spend vs cap, rate use, ETA.

On a terminal it is a rich live panel refreshed a few times a second; otherwise (a log file, a
CI job, a test) it prints one plain line at most every ``line_every_s`` seconds, so an overnight
log stays readable.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from typing import Any

from rich.console import Console
from rich.live import Live
from rich.markup import escape
from rich.panel import Panel
from rich.progress_bar import ProgressBar
from rich.table import Table
from rich.text import Text

from pipeline.backend import RateStats

#: how the driver marks a test-double model's label in the rates (see pipeline.summary)
TEST_DOUBLE_MARK = "(test double)"


@dataclass
class Snapshot:
    """The figures one progress refresh shows; ``eta_s`` and ``run_cap_usd`` are None when unknown or uncapped,
    ``stopped`` names the cap that stopped new work."""

    total: int
    done: int
    success: int
    running: int
    spend_usd: float
    run_cap_usd: float | None
    eta_s: float | None
    rates: dict[str, RateStats] = field(default_factory=dict)
    restarts: int = 0
    stopped: str | None = None


def paused_text(until: float | None, now: float | None = None) -> str:
    """ "  paused until HH:MM:SS" while a provider's Retry-After holds a model back, else ""."""
    now = time.time() if now is None else now
    if until is None or until <= now:
        return ""
    return "  paused until " + time.strftime("%H:%M:%S", time.localtime(until))


def eta_text(s: Snapshot) -> str:
    """No ETA once a cap has stopped new work: what is left waits for a resume."""
    return "-- (stopped)" if s.stopped else fmt_duration(s.eta_s)


def nominal(s: Snapshot) -> str:
    """Spend of test-double models is a nominal price, not money: say so beside the figure."""
    return " (nominal: test doubles)" if s.rates and all(TEST_DOUBLE_MARK in m for m in s.rates) else ""


def fmt_duration(seconds: float | None) -> str:
    """A duration as ``1h05m`` or ``4m07s`` (rounded to the second); ``--`` when unknown."""
    if seconds is None:
        return "--"
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}h{m:02d}m" if h else f"{m}m{s:02d}s"


def _pct(used: float | None, limit: float | None) -> str:
    if used is None:
        return "--"
    if not limit:
        return f"{used:.0f}"
    return f"{used:.0f}/{limit:.0f} ({100 * used / limit:.0f}%)"


def status_line(s: Snapshot) -> str:
    """The one-line form of a snapshot (the ``lines`` mode and logs): units, success, spend vs cap, ETA,
    restarts, per-model rate use."""
    cap = f" / cap ${s.run_cap_usd:.2f}" if s.run_cap_usd is not None else ""
    rate = "; ".join(
        f"{m}: rpm {_pct(r.rpm, r.rpm_limit)} tpm {_pct(r.tpm, r.tpm_limit)}{paused_text(r.paused_until)}"
        for m, r in s.rates.items()
    )
    line = (
        f"units {s.done}/{s.total} | success {s.success}/{s.done} | running {s.running} | "
        f"spend ${s.spend_usd:.4f}{cap}{nominal(s)} | ETA {eta_text(s)}"
    )
    if s.restarts:
        line += f" | worker restarts {s.restarts}"
    if rate:
        line += f" | {rate}"
    if s.stopped:
        line += f" | {s.stopped}"
    return line


class ProgressView:
    """``mode``: ``live`` (rich panel), ``lines`` (plain periodic lines) or ``off``."""

    def __init__(self, mode: str = "auto", *, title: str = "", line_every_s: float = 10.0, stream: Any = None) -> None:
        self.stream = stream or sys.stdout
        if mode == "auto":
            mode = "live" if getattr(self.stream, "isatty", lambda: False)() else "lines"
        self.mode = mode
        self.title = title
        self.line_every_s = line_every_s
        self._last_line = 0.0
        self._live: Any = None

    def __enter__(self) -> ProgressView:
        if self.mode == "live":
            self._live = Live(self._render(None), console=Console(file=self.stream), refresh_per_second=4, transient=False)
            self._live.__enter__()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self._live is not None:
            self._live.__exit__(*exc)
            self._live = None

    def _render(self, s: Snapshot | None) -> Any:
        t = Table.grid(padding=(0, 2))
        t.add_column(style="bold")
        t.add_column()
        if s is None:
            t.add_row("starting", "")
            return Panel(t, title=escape(self.title))
        t.add_row("units", f"{s.done}/{s.total}  (running {s.running})")
        t.add_row("", ProgressBar(total=max(s.total, 1), completed=s.done, width=40))
        rate = f"{100 * s.success / s.done:.1f}%" if s.done else "--"
        t.add_row("success", f"{s.success}/{s.done}  {rate}")
        cap = f" of ${s.run_cap_usd:.2f} cap ({100 * s.spend_usd / s.run_cap_usd:.0f}%)" if s.run_cap_usd else ""
        t.add_row("spend", f"${s.spend_usd:.4f}{cap}{nominal(s)}")
        for m, r in s.rates.items():
            t.add_row(
                escape(f"{m}"),
                f"rpm {_pct(r.rpm, r.rpm_limit)}  tpm {_pct(r.tpm, r.tpm_limit)}"
                + (f"  in flight {r.in_flight}" if r.in_flight is not None else "")
                + paused_text(r.paused_until),
            )
        t.add_row("ETA", eta_text(s))
        if s.restarts:
            t.add_row("restarts", str(s.restarts))
        if s.stopped:
            t.add_row("stopped", f"[yellow]{escape(s.stopped)}[/yellow]")
        return Panel(t, title=escape(self.title))

    def note(self, text: str) -> None:
        """One line the user must see whatever the mode (a stop under way): above the live
        panel, else on stderr."""
        if self._live is not None:
            self._live.console.print(Text(text, style="yellow"))
        else:
            print(text, file=sys.stderr, flush=True)

    def update(self, s: Snapshot, *, force: bool = False) -> None:
        """Show ``s``: the live panel at once; in ``lines`` mode a line at most every ``line_every_s`` seconds
        unless ``force`` (the final line)."""
        if self.mode == "live" and self._live is not None:
            self._live.update(self._render(s))
        elif self.mode == "lines":
            now = time.monotonic()
            if force or now - self._last_line >= self.line_every_s:
                self._last_line = now
                print(status_line(s), file=self.stream, flush=True)
