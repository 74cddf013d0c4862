"""Model prices from the repo's table, and costs as exact integers.

Why a table in the repo: a run's cost must be reproducible from its raw token counts, not
depend on whatever a library version believes a model costs. litellm's own cost is kept only
as a cross-check. Prices are USD per million tokens (input, cached input, cache write, output);
a sweep may override any model's price.

Prompt caching: the prompt tokens a provider reports are split three ways - read from its
cache (``cached_input`` price), written to it (``cache_write`` price: Anthropic bills a
write at 1.25x the input price; OpenAI and DeepSeek write for free, so their entries leave it
out and a write costs the plain input price), and the rest (``input`` price). A model whose
provider caches only at explicit breakpoints (``explicit_cache: true``) gets cache markers
from the gateway (:mod:`workers.llm.cache_markers`).

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
    """USD per million tokens. ``cached_input`` and ``cache_write`` default to ``input`` (no
    cache discount, no write surcharge)."""

    input: float
    output: float
    cached_input: float | None = None
    test_double: bool = False
    note: str = ""
    cache_write: float | None = None
    #: the provider caches only prefixes ending at explicit ``cache_control`` breakpoints
    explicit_cache: bool = False

    def __post_init__(self) -> None:
        # validate once; the integer rates are derived on demand
        self.rates()
        self.write_rate()

    def rates(self) -> tuple[int, int, int]:
        """(input, cached input, output) in pico-USD per token."""
        cached = self.input if self.cached_input is None else self.cached_input
        return (
            _pico_per_token(self.input, "input"),
            _pico_per_token(cached, "cached_input"),
            _pico_per_token(self.output, "output"),
        )

    def write_rate(self) -> int:
        """Cache-write price in pico-USD per token (the input price when not set)."""
        return _pico_per_token(self.input if self.cache_write is None else self.cache_write, "cache_write")

    def max_input_rate(self) -> int:
        """The dearest price a prompt token can have (what a worst case reserves per token)."""
        r_in, r_cached, _ = self.rates()
        return max(r_in, r_cached, self.write_rate())

    def cost_pico(
        self, prompt_tokens: int, cached_prompt_tokens: int, completion_tokens: int, cache_write_tokens: int = 0
    ) -> int:
        """Cost in pico-USD; cached (read) and cache-write tokens are parts of the prompt tokens
        (clamped so that together they never exceed it)."""
        cached = max(0, min(cached_prompt_tokens, prompt_tokens))
        written = max(0, min(cache_write_tokens, prompt_tokens - cached))
        r_in, r_cached, r_out = self.rates()
        return (
            (prompt_tokens - cached - written) * r_in
            + cached * r_cached
            + written * self.write_rate()
            + completion_tokens * r_out
        )

    def cost_usd(
        self, prompt_tokens: int, cached_prompt_tokens: int, completion_tokens: int, cache_write_tokens: int = 0
    ) -> float:
        return pico_to_usd(self.cost_pico(prompt_tokens, cached_prompt_tokens, completion_tokens, cache_write_tokens))

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any], what: str) -> Price:
        unknown = set(data) - {"input", "output", "cached_input", "cache_write", "explicit_cache", "test_double", "note"}
        if unknown:
            raise PriceError(f"{what}: unknown price field(s) {sorted(unknown)}")
        for required in ("input", "output"):
            if required not in data:
                raise PriceError(f"{what}: price needs {required!r} (USD per million tokens)")
        for flag in ("explicit_cache", "test_double"):
            if flag in data and not isinstance(data[flag], bool):
                raise PriceError(f"{what}: {flag} must be true or false, got {data[flag]!r}")
        try:
            return cls(
                input=float(data["input"]),
                output=float(data["output"]),
                cached_input=None if data.get("cached_input") is None else float(data["cached_input"]),
                cache_write=None if data.get("cache_write") is None else float(data["cache_write"]),
                explicit_cache=bool(data.get("explicit_cache", False)),
                test_double=bool(data.get("test_double", False)),
                note=str(data.get("note", "")),
            )
        except (TypeError, ValueError) as exc:
            raise PriceError(f"{what}: {exc}") from None


def pico_to_usd(pico: int) -> float:
    """An integer amount of pico-USD (1e-12 USD) as float USD, for display and records; sums and cap
    checks stay in pico."""
    return pico / PICO


def usd_to_pico(usd: float) -> int:
    """A USD amount (a cap) as pico-USD, rounded down so a cap is never loosened."""
    return int(Decimal(str(usd)) * PICO)


class PriceTable:
    """Prices by model string. Lookup: exact name, then the name without its provider prefix."""

    def __init__(self, prices: Mapping[str, Price]):
        self._prices = dict(prices)

    @classmethod
    def load(cls, path: Path | str = PRICES_FILE) -> PriceTable:
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

    def with_overrides(self, overrides: Mapping[str, Any] | None) -> PriceTable:
        """A copy where ``overrides`` (model -> Price or mapping) replace table entries."""
        merged = dict(self._prices)
        for model, price in (overrides or {}).items():
            merged[model] = price if isinstance(price, Price) else Price.from_mapping(price, f"override {model}")
        return PriceTable(merged)


@lru_cache(maxsize=1)
def default_prices() -> PriceTable:
    """The repo's table (read once per process)."""
    return PriceTable.load()


def resolve_price(model: str, override: Price | Mapping[str, Any] | None = None, table: PriceTable | None = None) -> Price | None:
    """The price of ``model``: the sweep's ``override`` when given (a mapping is validated,
    PriceError), else the table's (default: the repo table); None when it has none."""
    if override is not None:
        return override if isinstance(override, Price) else Price.from_mapping(override, f"override {model}")
    return (table or default_prices()).get(model)


def require_prices(
    models: Iterable[str], overrides: Mapping[str, Any] | None = None, table: PriceTable | None = None
) -> dict[str, Price]:
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
            "(USD per million tokens: input, cached_input, cache_write, output)"
        )
    return found
