"""The Robotouille domain (object types, predicates, actions) parsed from its JSON description.

The engine interprets the domain rather than hard-coding it, so the same code runs any domain file
of the same shape. Parsing happens once per file (the result is immutable and shared); a domain
that refers to an unknown predicate or effect type is rejected with the offending name.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .data import DataFileError, domain_json

EFFECT_KINDS = ("immediate", "delayed", "repetitive", "conditional", "creation", "deletion")


@dataclass(frozen=True)
class PredicateDef:
    """A predicate of the domain: its argument types and, per argument, the sentence that describes it from that object's side."""

    name: str
    param_types: tuple[str, ...]
    #: sentence template per argument position ("{0} is at {1}")
    sentences: tuple[str, ...]


@dataclass(frozen=True)
class Literal:
    """A predicate over action parameters (``p1``, ``s1``...) with the truth value it needs/sets."""

    predicate: str
    params: tuple[str, ...]
    is_true: bool


@dataclass(frozen=True)
class CreatedObject:
    """The object a creation effect makes: its name, type, and the action parameter it is made from."""

    name: str
    type: str
    param: str


@dataclass(frozen=True)
class EffectSpec:
    """A special effect template of an action; bound to objects when the action is taken."""

    kind: str
    param: str
    fx: tuple[Literal, ...]
    nested: tuple[EffectSpec, ...]
    conditions: tuple[Literal, ...] = ()
    created: CreatedObject | None = None


@dataclass(frozen=True)
class ActionDef:
    """An action of the domain: its parameters, preconditions, immediate and special effects, and its language description."""

    name: str
    #: (parameter, object type) in order of first appearance
    params: tuple[tuple[str, str], ...]
    precons: tuple[Literal, ...]
    immediate_fx: tuple[Literal, ...]
    sfx: tuple[EffectSpec, ...]
    description: str


@dataclass(frozen=True)
class Domain:
    """A parsed domain file: object types, predicates (in file order, which orders the sentences of an
    observation) and actions. Immutable, shared by every state."""

    name: str
    object_types: tuple[str, ...]
    predicates: tuple[PredicateDef, ...]
    actions: tuple[ActionDef, ...]
    #: name -> predicate and name -> position, filled in by __post_init__ (the class is frozen)
    _by_name: dict[str, PredicateDef] = field(init=False, repr=False, compare=False)
    _order: dict[str, int] = field(init=False, repr=False, compare=False)

    def predicate(self, name: str) -> PredicateDef:
        """The predicate named ``name``; KeyError for a name not in the domain."""
        return self._by_name[name]

    def predicate_index(self, name: str) -> int:
        """The position of predicate ``name`` in the domain file: the order its sentences take in an object's description."""
        return self._order[name]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {p.name: p for p in self.predicates})
        object.__setattr__(self, "_order", {p.name: i for i, p in enumerate(self.predicates)})


def _literal(raw: Any, where: str, preds: dict[str, PredicateDef]) -> Literal:
    name = raw.get("predicate")
    if name not in preds:
        raise DataFileError(f"domain: {where} uses unknown predicate {name!r}")
    params = tuple(raw.get("params", ()))
    if len(params) != len(preds[name].param_types):
        raise DataFileError(f"domain: {where}: {name} takes {len(preds[name].param_types)} params")
    return Literal(name, params, bool(raw.get("is_true", True)))


def _effect(raw: Any, where: str, preds: dict[str, PredicateDef]) -> EffectSpec:
    kind = raw.get("type")
    if kind not in EFFECT_KINDS:
        raise DataFileError(f"domain: {where} has unknown special effect type {kind!r}")
    created = None
    if kind == "creation":
        obj = raw.get("created_obj") or {}
        created = CreatedObject(obj["name"], obj["type"], obj["param"])
    return EffectSpec(
        kind=kind,
        param=raw["param"],
        fx=tuple(_literal(f, where, preds) for f in raw.get("fx", ())),
        nested=tuple(_effect(s, where, preds) for s in raw.get("sfx", ())),
        conditions=tuple(_literal(c, where, preds) for c in raw.get("conditions", ())),
        created=created,
    )


def _literals_of(effect: EffectSpec):
    yield from effect.conditions
    yield from effect.fx
    for nested in effect.nested:
        yield from _literals_of(nested)


def _action_params(precons, fx, sfx, preds) -> tuple[tuple[str, str], ...]:
    """Parameters in order of first appearance; types from the predicates they fill.

    A parameter bound only by a creation effect (the created object) is not an action parameter.
    """
    created = set()

    def collect_created(e: EffectSpec) -> None:
        if e.created is not None:
            created.add(e.created.param)
        for n in e.nested:
            collect_created(n)

    for e in sfx:
        collect_created(e)
    seen: dict[str, str] = {}
    literals = list(precons) + list(fx) + [lit for e in sfx for lit in _literals_of(e)]
    for lit in literals:
        for param, ptype in zip(lit.params, preds[lit.predicate].param_types):
            if param not in seen and param not in created:
                seen[param] = ptype
    for e in sfx:
        if e.param not in seen and e.param not in created:
            raise DataFileError(f"domain: special effect parameter {e.param!r} has no type")
    return tuple(seen.items())


def parse_domain(raw: Any, source: str = "domain") -> Domain:
    """Parse a domain JSON (``source`` names it in errors); DataFileError for a malformed one or one that names
    an unknown predicate or effect type."""
    try:
        preds: dict[str, PredicateDef] = {}
        ordered = []
        for p in raw["predicate_defs"]:
            types = tuple(p["param_types"])
            desc = p["language_descriptors"]
            pd = PredicateDef(p["name"], types, tuple(desc[str(i)] for i in range(len(types))))
            preds[pd.name] = pd
            ordered.append(pd)
        actions = []
        for a in raw["action_defs"]:
            where = f"action {a['name']!r}"
            precons = tuple(_literal(x, where, preds) for x in a.get("precons", ()))
            fx = tuple(_literal(x, where, preds) for x in a.get("immediate_fx", ()))
            sfx = tuple(_effect(x, where, preds) for x in a.get("sfx", ()))
            actions.append(
                ActionDef(
                    name=a["name"],
                    params=_action_params(precons, fx, sfx, preds),
                    precons=precons,
                    immediate_fx=fx,
                    sfx=sfx,
                    description=a["language_description"],
                )
            )
        return Domain(raw.get("name", "robotouille"), tuple(raw["object_types"]), tuple(ordered), tuple(actions))
    except (KeyError, TypeError, AttributeError) as exc:
        raise DataFileError(f"{source}: not a Robotouille domain ({type(exc).__name__}: {exc})") from None


_DOMAINS: dict[tuple[str, int], Domain] = {}


def load_domain(data_dir: Path) -> Domain:
    """The parsed domain of a data folder (parsed once per process and file version)."""
    raw = domain_json(data_dir)
    key = (str(data_dir), id(raw))
    dom = _DOMAINS.get(key)
    if dom is None:
        dom = parse_domain(raw, str(data_dir / "domain/robotouille.json"))
        _DOMAINS[key] = dom
    return dom
