"""Model prices from the repo's table, and costs as exact integers.

Why a table in the repo: a run's cost must be reproducible from its raw token counts, not
depend on whatever a library version believes a model costs. litellm's own cost is kept only
as a cross-check. Prices are USD per million tokens (input, cached input, output); a sweep
may override any model's price.

Costs are computed in integer pico-dollars (1e-12 USD): sums and cap comparisons are then
exact, so a restarted ledger restores *exactly* the spend it had, and ``spend <= cap`` is
never disturbed by float rounding. Prices may have at most six decimals (USD per million).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from functools import lru_cache
from pathlib import Path
from typing import Any

import yaml

PRICES_FILE = Path(__file__).resolve().parents[1] / "pricing" / "prices.yaml"
PICO = 10**12


class PriceError(ValueError):
    """A price entry is missing or malformed."""


def _pico_per_token(value: Any, what: str) -> int:
    """USD per million tokens -> integer pico-USD per token (exact for <= 6 decimals)."""
    try:
        d = Decimal(str(value))
    except InvalidOperation:
        raise PriceError(f"{what}: price {value!r} is not a number") from None
    if d < 0:
        raise PriceError(f"{what}: price {value} is negative")
    pico = d * 10**6
    if pico != pico.to_integral_value():
        raise PriceError(f"{what}: price {value} has more than 6 decimals (USD per 1M tokens)")
    return int(pico)


@dataclass(frozen=True)
class Price:
    """USD per million tokens. ``cached_input`` defaults to ``input`` (no cache discount)."""

    input: float
    output: float
    cached_input: float | None = None
    test_double: bool = False
    note: str = ""

    def __post_init__(self) -> None:
        # validate once; the integer rates are derived on demand
        self.rates()

    def rates(self) -> tuple[int, int, int]:
        """(input, cached input, output) in pico-USD per token."""
        cached = self.input if self.cached_input is None else self.cached_input
        return (
            _pico_per_token(self.input, "input"),
            _pico_per_token(cached, "cached_input"),
            _pico_per_token(self.output, "output"),
        )

    def cost_pico(self, prompt_tokens: int, cached_prompt_tokens: int, completion_tokens: int) -> int:
        """Cost in pico-USD; cached tokens are a part of the prompt tokens."""
        cached = max(0, min(cached_prompt_tokens, prompt_tokens))
        r_in, r_cached, r_out = self.rates()
        return (prompt_tokens - cached) * r_in + cached * r_cached + completion_tokens * r_out

    def cost_usd(self, prompt_tokens: int, cached_prompt_tokens: int, completion_tokens: int) -> float:
        return pico_to_usd(self.cost_pico(prompt_tokens, cached_prompt_tokens, completion_tokens))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], what: str) -> "Price":
        unknown = set(data) - {"input", "output", "cached_input", "test_double", "note"}
        if unknown:
            raise PriceError(f"{what}: unknown price field(s) {sorted(unknown)}")
        for required in ("input", "output"):
            if required not in data:
                raise PriceError(f"{what}: price needs {required!r} (USD per million tokens)")
        try:
            return cls(
                input=float(data["input"]),
                output=float(data["output"]),
                cached_input=None if data.get("cached_input") is None else float(data["cached_input"]),
                test_double=bool(data.get("test_double", False)),
                note=str(data.get("note", "")),
            )
        except (TypeError, ValueError) as exc:
            raise PriceError(f"{what}: {exc}") from None


def pico_to_usd(pico: int) -> float:
    return pico / PICO


def usd_to_pico(usd: float) -> int:
    """A USD amount (a cap) as pico-USD, rounded down so a cap is never loosened."""
    return int(Decimal(str(usd)) * PICO)


class PriceTable:
    """Prices by model string. Lookup: exact name, then the name without its provider prefix."""

    def __init__(self, prices: Mapping[str, Price]):
        self._prices = dict(prices)

    @classmethod
    def load(cls, path: Path | str = PRICES_FILE) -> "PriceTable":
        path = Path(path)
        try:
            data = yaml.safe_load(path.read_text())
        except FileNotFoundError:
            raise PriceError(f"price table {path} does not exist") from None
        models = (data or {}).get("models")
        if not isinstance(models, dict):
            raise PriceError(f"price table {path} needs a 'models:' mapping")
        return cls({name: Price.from_mapping(v or {}, f"{path.name}: {name}") for name, v in models.items()})

    def get(self, model: str) -> Price | None:
        if model in self._prices:
            return self._prices[model]
        if "/" in model:
            return self._prices.get(model.split("/", 1)[1])
        return None

    def models(self) -> list[str]:
        return sorted(self._prices)

    def with_overrides(self, overrides: Mapping[str, Any] | None) -> "PriceTable":
        """A copy where ``overrides`` (model -> Price or mapping) replace table entries."""
        merged = dict(self._prices)
        for model, price in (overrides or {}).items():
            merged[model] = price if isinstance(price, Price) else Price.from_mapping(price, f"override {model}")
        return PriceTable(merged)


@lru_cache(maxsize=1)
def default_prices() -> PriceTable:
    """The repo's table (read once per process)."""
    return PriceTable.load()


def resolve_price(model: str, override: Price | Mapping[str, Any] | None = None,
                  table: PriceTable | None = None) -> Price | None:
    if override is not None:
        return override if isinstance(override, Price) else Price.from_mapping(override, f"override {model}")
    return (table or default_prices()).get(model)


def require_prices(models: Iterable[str], overrides: Mapping[str, Any] | None = None,
                   table: PriceTable | None = None) -> dict[str, Price]:
    """Every model's price, or one PriceError naming all models without one.

    A capped sweep calls this before it starts: a cap cannot be enforced for a model whose
    calls cannot be priced.
    """
    table = (table or default_prices()).with_overrides(overrides)
    found: dict[str, Price] = {}
    missing: list[str] = []
    for model in models:
        price = table.get(model)
        if price is None:
            missing.append(model)
        else:
            found[model] = price
    if missing:
        raise PriceError(
            f"no price for model(s) {', '.join(sorted(set(missing)))}: add them to "
            f"{PRICES_FILE.relative_to(PRICES_FILE.parents[2])} or pass a price override "
            "(USD per million tokens: input, cached_input, output)"
        )
    return found
