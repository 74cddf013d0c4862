"""What crosses the worker -> driver seam and the budget -> driver seam, typed.

Why here: the episode worker (``workers/``) produces an attempt's outcome and the driver
(``pipeline/``) turns it into the terminal ``episodes`` row; the budget (``workers/gateway``)
refuses a call and the driver decides which cap stopped the run. Both sides import these
types from ``schemas/`` (the one package every layer may import), so a field renamed on one
side is a type error on the other, not a silently defaulted ``.get(..., 0)``.

Everything here is a plain frozen dataclass: it pickles across Ray and has no behaviour
beyond formatting its own message.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from schemas.kinds import EndReason

#: which cap refused a call: the run's, the model's, or a capped run that cannot price the model;
#: or ``usage``: the model's provider reported impossible usage too often, its calls are refused;
#: or ``episode``: the call's worst case would take its episode past the per-instance cap
#: (``limits.usd``) - that episode ends ``episode_limit``, nothing else stops
RefusalScope = Literal["run", "model", "unpriced", "usage", "episode"]
REFUSAL_SCOPES: tuple[RefusalScope, ...] = ("run", "model", "unpriced", "usage", "episode")

#: where an attempt crashed (not: ended): the model client, or the agent's own code
CrashSource = Literal["client", "agent"]

_PICO = 10**12


def _usd(pico: int) -> str:
    return f"${pico / _PICO:.6f}"


@dataclass(frozen=True)
class BudgetRefusal:
    """The budget's answer when a call would pass a cap (amounts in pico-USD, as the ledger
    keeps them, so the message is exact).

    ``model`` is the name the ledger keys caps by: the deployment's name, which in a sweep is
    the model's name (its label, else its model string); the driver also knows which unit (and
    so which model) was refused."""

    scope: RefusalScope
    model: str
    cap_pico: int | None = None
    committed_pico: int = 0
    worst_pico: int | None = None
    #: scope ``usage``: the replies whose usage was rejected as impossible (the limit reached)
    rejected: int = 0

    def __post_init__(self) -> None:
        if self.scope not in REFUSAL_SCOPES:
            raise ValueError(f"unknown refusal scope {self.scope!r}; known: {', '.join(REFUSAL_SCOPES)}")

    @property
    def message(self) -> str:
        """The one line an episode row's ``error`` carries."""
        if self.scope == "unpriced":
            return (
                f"no price for model {self.model}: a capped run cannot price its calls "
                "(add it to workers/pricing/prices.yaml or pass a price override)"
            )
        if self.scope == "usage":
            return (
                f"{self.model}: provider usage rejected as impossible in {self.rejected} replies "
                "(each charged at its worst case); no more calls to it this session"
            )
        if self.scope == "episode":
            return (
                f"episode budget: spent {_usd(self.committed_pico)} + this call's worst case "
                f"{_usd(self.worst_pico or 0)} > the per-instance cap {_usd(self.cap_pico or 0)}"
            )
        who = "run" if self.scope == "run" else self.model
        return (
            f"{who} budget: committed {_usd(self.committed_pico)} + this call's worst case "
            f"{_usd(self.worst_pico or 0)} > cap {_usd(self.cap_pico or 0)}"
        )

    def to_dict(self) -> dict[str, Any]:
        """The refusal as plain JSON types, as the ledger answers a gateway's reservation (:meth:`from_dict` reads it back)."""
        out: dict[str, Any] = {
            "scope": self.scope,
            "model": self.model,
            "cap_pico": self.cap_pico,
            "committed_pico": self.committed_pico,
            "worst_pico": self.worst_pico,
        }
        if self.scope == "usage":
            out["rejected"] = self.rejected
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> BudgetRefusal:
        """The refusal from :meth:`to_dict`'s form; a missing committed amount reads as 0, an unknown scope raises ValueError."""
        return cls(
            scope=d["scope"],
            model=d["model"],
            cap_pico=d.get("cap_pico"),
            committed_pico=int(d.get("committed_pico") or 0),
            worst_pico=d.get("worst_pico"),
            rejected=int(d.get("rejected") or 0),
        )


@dataclass
class EpisodeResult:
    """How an episode ended and what it used, as the agent's runtime counts it
    (:meth:`recap.runtime.Episode.result`). ``refusal`` is set when the episode ended
    ``budget_exhausted``: the cap that refused its call."""

    end_reason: EndReason
    success: bool
    steps: int
    llm_calls: int
    prompt_tokens: int = 0
    cached_prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    max_depth: int = 0
    invalid_actions: int = 0
    json_repairs: int = 0
    error: str | None = None
    error_kind: str | None = None
    refusal: BudgetRefusal | None = None


@dataclass(frozen=True)
class EnvFacts:
    """The episode's place and step budget, as its environment reports them (``split`` and
    ``task`` empty when the environment could not be built)."""

    benchmark: str
    split: str = ""
    task: str = ""
    optimal_steps: int | None = None
    max_steps: int = 0


@dataclass(frozen=True)
class Crash:
    """An attempt that did not end but broke: the driver retries it (up to ``max_attempts``)."""

    source: CrashSource
    error: str
    traceback: str = ""


@dataclass
class EpisodeOutcome:
    """What a worker returns for one attempt of one unit.

    Exactly one of ``result`` (the episode ended, successfully or not) and ``crash`` (it broke)
    is set once the worker returns; ``model`` is the provider model that answered (the unit's
    own unless a router chose another)."""

    unit_id: str
    attempt: int
    episode_id: str
    worker_id: str
    pid: int
    started_at: float
    env: EnvFacts
    model: str
    test_double: bool
    result: EpisodeResult | None = None
    crash: Crash | None = None
    ended_at: float = 0.0
    wall_s: float = 0.0
    rows_sent: int = 0


@dataclass(frozen=True)
class UnitWork:
    """What the driver hands a worker for one unit: the instance, the method with its
    *resolved* settings (``method_config``, the canonical JSON the unit's hash covers: the
    worker builds the agent from it, never from the sweep's raw profile/ablation/settings),
    the model, the sampling seed and the environment's options."""

    unit_id: str
    instance_id: str
    method: str
    method_config: str
    model_label: str
    model: str
    sampling_seed: int
    step_multiplier: float
    env_options: tuple[tuple[str, Any], ...] = ()

    @property
    def benchmark(self) -> str:
        """The benchmark name: the instance id up to its first ``/``."""
        return self.instance_id.split("/", 1)[0]
