"""Deterministic error injection for the offline test doubles.

Why: the agents' recovery paths (malformed JSON repair, leaf failure, invalid-action feedback)
must be exercised without a real model, and a failing test must fail the same way every time.
Every random choice is drawn from a generator seeded by (noise_seed, call_key), so a call's
outcome depends only on those two - not on call order, process or concurrency. ``noise_seed`` (the
``options`` key; ``seed`` is its old name, still read) is the double's own: neither the unit's
sampling seed nor an instance's layout seed.
"""

from __future__ import annotations

import hashlib
import random
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from schemas.ranges import range_problem

#: an action no benchmark has; injected to make the agent meet an invalid action
INVALID_ACTION = "xyzzy the unknown object (injected invalid action)"
#: a reply cut in the middle of its JSON object; injected to exercise the repair path
MALFORMED_JSON = '{"think": "the reply stops in the middle of'


#: every option's range (both ends inclusive), said in the refusal; a sweep file's numbers all
#: have one (tests/pipeline/test_spec_bounds.py)
KNOB_BOUNDS: dict[str, tuple[float, float]] = {
    "noise_seed": (0, 2**63 - 1),
    "invalid_action_rate": (0.0, 1.0),
    "malformed_json_rate": (0.0, 1.0),
    "chunk_size": (1, 1000),
}


#: the old name of the ``noise_seed`` option (sweep files and run folders written before it)
OLD_NOISE_SEED = "seed"


class OfflineOptionsError(ValueError):
    """Bad options for an offline test double."""


def renamed_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` with the old ``seed`` key read as ``noise_seed``; both at once is an error."""
    out = dict(options or {})
    if OLD_NOISE_SEED in out:
        if "noise_seed" in out:
            raise OfflineOptionsError(f"give noise_seed or its old name {OLD_NOISE_SEED}, not both")
        out = {("noise_seed" if k == OLD_NOISE_SEED else k): v for k, v in out.items()}
    return out


def hashed_options(options: Mapping[str, Any]) -> dict[str, Any]:
    """The options as a unit's hash covers them: ``noise_seed`` under its old name ``seed``, so
    that both spellings, and runs written before the rename, give the same unit ids. Both keys at
    once are left as they are (the plan is expanded before the models are checked, which refuses
    them: :func:`renamed_options`)."""
    if OLD_NOISE_SEED in options:
        return dict(options)
    return {(OLD_NOISE_SEED if k == "noise_seed" else k): v for k, v in options.items()}


@dataclass(frozen=True)
class Knobs:
    """The options of an offline/ test double (a sweep model's ``options``): the noise seed and
    rates of the injected errors, and offline/expert's root chunk size."""

    noise_seed: int = 0
    invalid_action_rate: float = 0.0
    malformed_json_rate: float = 0.0
    #: actions per subgoal chunk of offline/expert at the root (None: at most 4 chunks)
    chunk_size: int | None = None

    @classmethod
    def from_options(cls, options: Mapping[str, Any] | None) -> Knobs:
        given = dict(options or {})
        options = renamed_options(given)
        unknown = set(options) - {"noise_seed", "invalid_action_rate", "malformed_json_rate", "chunk_size"}
        if unknown:
            raise OfflineOptionsError(f"unknown offline model option(s) {sorted(unknown)}")
        for name, value in given.items():  # no int() of 2.7 or of true: a number is kept as given
            option = "noise_seed" if name == OLD_NOISE_SEED else name  # named as the file names it
            integer = option in ("noise_seed", "chunk_size")
            if value is None and option == "chunk_size":
                continue
            problem = range_problem(value, integer, *KNOB_BOUNDS[option])
            if problem is not None:
                raise OfflineOptionsError(f"{name} {problem}")
        knobs = cls(
            noise_seed=options.get("noise_seed", 0),
            invalid_action_rate=float(options.get("invalid_action_rate", 0.0)),
            malformed_json_rate=float(options.get("malformed_json_rate", 0.0)),
            chunk_size=options.get("chunk_size"),
        )
        return knobs


def call_rng(call_key: str, noise_seed: int, salt: str) -> random.Random:
    """A generator that depends only on (noise_seed, call_key, salt)."""
    digest = hashlib.sha256(f"{noise_seed}|{call_key}|{salt}".encode()).digest()
    return random.Random(int.from_bytes(digest[:8], "big"))


def draw(call_key: str, noise_seed: int, salt: str) -> float:
    """A number in [0, 1) fixed by (noise_seed, call_key, salt): compared with a rate, it decides whether
    this call gets an injected error (``salt`` keeps the kinds of error independent)."""
    return call_rng(call_key, noise_seed, salt).random()
