"""When the driver stops starting episodes: the run's cap and each model's cap.

Why its own object: the budget (the ledger behind the gateways) refuses any call that would
pass a cap, so no cap can be overspent; this policy only decides what the driver stops
*starting*. It reads two signals - the live spend (a cap reached) and a typed
:class:`schemas.outcomes.BudgetRefusal` from an episode that ended ``budget_exhausted`` (a cap
that would be passed) - and stops either the whole run or one model, recording an event each
time it stops something.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.backend import Spend
from pipeline.spec import SweepSpec
from schemas.outcomes import BudgetRefusal

#: spend within this of a cap counts as reaching it (float sums of pico-exact amounts)
EPS = 1e-12


class CapPolicy:
    """Which models (or the whole run) the driver no longer starts episodes for."""

    def __init__(self, spec: SweepSpec, event: Callable[..., None]) -> None:
        self.spec = spec
        self._event = event
        #: why the whole run stopped (None while it runs)
        self.run_stopped: str | None = None
        #: model labels whose cap was reached
        self.stopped_models: set[str] = set()

    def allows(self, model_label: str) -> bool:
        """May an episode of this model start now?"""
        return self.run_stopped is None and model_label not in self.stopped_models

    @property
    def stopped(self) -> str | None:
        """One line on what stopped (the run's reason, else the capped models), or None."""
        if self.run_stopped:
            return self.run_stopped
        return ", ".join(sorted(self.stopped_models)) + " capped" if self.stopped_models else None

    def check(self, spend: Spend) -> None:
        """Stop what the live spend has reached the cap of."""
        cap = self.spec.run_cap_usd
        if self.run_stopped is None and cap is not None and spend.total_usd >= cap - EPS:
            self.stop_run(f"run cap ${cap:.2f} reached")  # the spend figure is the live one beside it
        for m in self.spec.models:
            if m.cap_usd is not None and m.name not in self.stopped_models and spend.by_model.get(m.name, 0.0) >= m.cap_usd - EPS:
                self.stop_model(m.name, f"model cap ${m.cap_usd:.2f} of {m.name} reached")

    def on_refusal(self, model_label: str, refusal: BudgetRefusal | None, error: str | None, spend: Spend) -> None:
        """An episode of ``model_label`` was refused a call: stop what refused it. The run when
        the refusal names the run's cap (or the model has no cap of its own), else the model."""
        m = self.spec.model(model_label)
        run_cap = self.spec.run_cap_usd
        if (refusal is not None and refusal.scope == "run") or m.cap_usd is None:
            self.stop_run(
                f"run cap ${run_cap:.2f} reached (spent ${spend.total_usd:.4f})"
                if run_cap is not None
                else f"a model call was refused for lack of budget: {error}"
            )
        else:
            self.stop_model(m.name, f"model cap ${m.cap_usd:.2f} of {m.name} reached")

    def stop_run(self, why: str) -> None:
        """Stop starting any unit (recorded once, with ``why``, as a ``run_cap_reached`` event); running episodes go on."""
        if self.run_stopped is None:
            self.run_stopped = why
            self._event("run_cap_reached", severity="warning", reason=why)

    def stop_model(self, name: str, why: str) -> None:
        """Stop starting units of model ``name`` (recorded once as a ``model_cap_reached`` event); other models go on."""
        if name not in self.stopped_models:
            self.stopped_models.add(name)
            self._event("model_cap_reached", severity="warning", model=name, reason=why)
