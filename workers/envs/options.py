"""The options a benchmark declares for a sweep's ``environments[].options``, in two kinds.

Why: a unit's id must change when what its episode does changes, and only then. A benchmark
therefore says, for each option a sweep may give it, whether the option

* changes what an episode does (:data:`EPISODE`: the sandbox kind and image, limits, grading,
  the Wikipedia source, the step cap...): part of the unit id, so a run whose option changed
  re-plans those units as ``changed``, as a changed method setting does; or
* changes only how it is run (:data:`RUN`: where the data is read from, a request rate, a
  politeness deadline, which instances a selector picks, whose ids already say so): not part of
  the unit id, so finished work is kept.

An option a benchmark does not declare is refused before anything runs (one line naming the
declared ones). A benchmark that declares nothing (:meth:`workers.envs.registry.Benchmark.declared_options`'s
default, as a third-party benchmark written before declarations) accepts no option at all.

Only an episode option whose value differs from its declared ``default`` enters the id: a sweep
that spells out a default (``sandbox: docker``) and one that leaves it out make the same units,
and the units of runs written before options were hashed keep their ids unless they set one
(:func:`pipeline.units.keep_earlier_ids` carries those over). An option whose default depends on
the method (ALFWorld's ``show_valid_actions``, swe-verified's ``container``) declares no default
(:data:`NO_DEFAULT`): given at all, it enters the id.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

#: the option changes what an episode does: part of the unit id
EPISODE: Literal["episode"] = "episode"
#: the option changes only how an episode is run: not part of the unit id
RUN: Literal["run"] = "run"
OptionKind = Literal["episode", "run"]


class _NoDefault:
    """The marker of an option whose default is not one fixed value (it depends on the method)."""

    def __repr__(self) -> str:
        return "NO_DEFAULT"


NO_DEFAULT: Any = _NoDefault()


@dataclass(frozen=True)
class EnvOption:
    """One declared option: its kind and, for an episode option, the value that counts as unset."""

    kind: OptionKind
    default: Any = NO_DEFAULT


def episode(default: Any = NO_DEFAULT) -> EnvOption:
    """An option that changes what an episode does (part of the unit id when not ``default``)."""
    return EnvOption(EPISODE, default)


def run(default: Any = NO_DEFAULT) -> EnvOption:
    """An option that changes only how an episode is run (never part of the unit id)."""
    return EnvOption(RUN, default)


def undeclared_problem(benchmark: str, declared: Mapping[str, EnvOption], given: Mapping[str, Any]) -> str | None:
    """One line naming the options of ``given`` that ``benchmark`` does not declare, or None."""
    unknown = sorted(set(given) - set(declared))
    if not unknown:
        return None
    if not declared:
        return (
            f"{benchmark} declares no options, got {', '.join(unknown)} "
            "(a benchmark declares them with Benchmark.declared_options)"
        )
    kinds = {k: sorted(n for n, o in declared.items() if o.kind == k) for k in (EPISODE, RUN)}
    return (
        f"unknown {benchmark} option(s) {', '.join(unknown)}; what an episode does: {', '.join(kinds[EPISODE]) or '-'}; "
        f"how it is run: {', '.join(kinds[RUN]) or '-'}"
    )


def _normal(value: Any) -> Any:
    """``value`` as the id hashes it: a whole float as an int (``60.0`` is ``60``)."""
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def _same(value: Any, default: Any) -> bool:
    """Whether ``value`` is the declared ``default`` (``true`` is not ``1``)."""
    if default is NO_DEFAULT or isinstance(value, bool) != isinstance(default, bool):
        return False
    return bool(_normal(value) == _normal(default))


def identity_options(declared: Mapping[str, EnvOption], given: Mapping[str, Any]) -> dict[str, Any]:
    """The options of ``given`` that are part of a unit's id: the episode options whose value is
    not their declared default (undeclared ones are left out: they are refused elsewhere)."""
    out: dict[str, Any] = {}
    for name, value in given.items():
        opt = declared.get(name)
        if opt is None or opt.kind != EPISODE:
            continue
        if _same(value, opt.default):
            continue
        out[name] = _normal(value)
    return dict(sorted(out.items()))
