"""When the driver stops starting episodes: the run's cap, each model's cap, a lying provider.

Why its own object: the budget (the ledger behind the gateways) refuses any call that would
pass a cap, so no cap can be overspent; this policy only decides what the driver stops
*starting*. It reads two signals - the live spend (a cap reached) and a typed
:class:`schemas.outcomes.BudgetRefusal` from an episode that ended ``budget_exhausted`` (a cap
that would be passed, or - scope ``usage`` - a provider whose usage the gateway rejected as
impossible too often) - and stops either the whole run or one model, recording an event each
time it stops something.

Its lines carry no spend figure: the spend at the moment a cap stopped the run is not what the
run spent in the end (calls in flight settle after it), and every figure printed reads the
ledger journal (:func:`pipeline.summary.collect`) instead.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.backend import Spend
from pipeline.spec import SweepSpec
from schemas.kinds import EventKind
from schemas.outcomes import BudgetRefusal

#: spend within this of a cap counts as reaching it (float sums of pico-exact amounts)
EPS = 1e-12


def usd(amount: float) -> str:
    """A cap as its lines show it: cents when that is exact (``$5.00``), else every digit that
    matters (``$0.005``, never a rounded ``$0.01``)."""
    cents = f"{amount:.2f}"
    return "$" + (cents if float(cents) == amount else f"{amount:.6f}".rstrip("0"))


class CapPolicy:
    """Which models (or the whole run) the driver no longer starts episodes for."""

    def __init__(self, spec: SweepSpec, event: Callable[..., None]) -> None:
        self.spec = spec
        self._event = event
        #: why the whole run stopped (None while it runs)
        self.run_stopped: str | None = None
        #: model labels whose cap was reached (or whose provider was stopped): the event kind
        #: that stopped each, and the line why
        self.stopped_models: dict[str, tuple[EventKind, str]] = {}

    def allows(self, model_label: str) -> bool:
        """May an episode of this model start now?"""
        return self.run_stopped is None and model_label not in self.stopped_models

    @property
    def stopped(self) -> str | None:
        """One line on what stopped (the run's reason, else the capped models), or None."""
        if self.run_stopped:
            return self.run_stopped
        capped = sorted(m for m, (kind, _) in self.stopped_models.items() if kind == "model_cap_reached")
        lines = [", ".join(capped) + " capped"] if capped else []
        lines += [why for m, (_, why) in sorted(self.stopped_models.items()) if m not in capped]
        return "; ".join(lines) if lines else None

    def check(self, spend: Spend) -> None:
        """Stop what the live spend has reached the cap of."""
        cap = self.spec.run_cap_usd
        if self.run_stopped is None and cap is not None and spend.total_usd >= cap - EPS:
            self.stop_run(f"run cap {usd(cap)} reached")
        for m in self.spec.models:
            if m.cap_usd is not None and m.name not in self.stopped_models and spend.by_model.get(m.name, 0.0) >= m.cap_usd - EPS:
                self.stop_model(m.name, f"model cap {usd(m.cap_usd)} of {m.name} reached")

    def on_refusal(self, model_label: str, refusal: BudgetRefusal | None, error: str | None, spend: Spend) -> None:
        """An episode of ``model_label`` was refused a call: stop what refused it. Only the model
        when its provider's usage was refused too often (``usage``: the other models go on); the
        run when the refusal names the run's cap (or the model has no cap of its own), else the model."""
        m = self.spec.model(model_label)
        run_cap = self.spec.run_cap_usd
        if refusal is not None and refusal.scope == "usage":
            self.stop_model(m.name, f"{m.name} stopped: {refusal.message}", kind="model_stopped")
        elif (refusal is not None and refusal.scope == "run") or m.cap_usd is None:
            self.stop_run(
                f"run cap {usd(run_cap)} reached"
                if run_cap is not None
                else f"a model call was refused for lack of budget: {error}"
            )
        else:
            self.stop_model(m.name, f"model cap {usd(m.cap_usd)} of {m.name} reached")

    def stop_run(self, why: str) -> None:
        """Stop starting any unit (recorded once, with ``why``, as a ``run_cap_reached`` event); running episodes go on."""
        if self.run_stopped is None:
            self.run_stopped = why
            self._event("run_cap_reached", severity="warning", reason=why)

    def stop_model(self, name: str, why: str, kind: EventKind = "model_cap_reached") -> None:
        """Stop starting units of model ``name`` (recorded once as a ``kind`` event: ``model_cap_reached``,
        or ``model_stopped`` for a provider stopped for its usage); other models go on."""
        if name not in self.stopped_models:
            self.stopped_models[name] = (kind, why)
            self._event(kind, severity="warning", model=name, reason=why)
