"""What a goal asks for, in cooking terms: stacked dishes on tables, soups in bowls, prep steps.

The expert planner reasons about dishes rather than raw predicates. This module reads a goal's
literals once and groups them:
- a *stack dish* on a table variable: a base item directly on the table (``item_on``), members
  anywhere in the stack (``item_at``) or at an exact place (``atop`` chains), and optionally a top
  item that must have nothing above it (``clear``);
- a *soup*: a water variable in a bowl (``in``), boiled (``isboiling``), with items added
  (``addedto``), the bowl on a table (``container_at``);
- per item variable, the preparation it needs (``iscut``, ``iscooked``, ``isfried``).
A goal with literals outside these shapes is reported as unsupported (the planner then has no plan).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .goal import Goal, GoalLiteral

PREP_PREDICATES = ("iscut", "iscooked", "isfried")
#: preparation the order it must happen in (cut before frying: onions become fryable once cut)
PREP_ORDER = ("iscut", "iscooked", "isfried")
#: preparation -> (station predicate, action name, object predicate that allows it)
PREP = {
    "iscut": ("isboard", "cut", "iscuttable"),
    "iscooked": ("isstove", "cook", "iscookable"),
    "isfried": ("isfryer", "fry", "isfryable"),
}


class UnsupportedGoal(ValueError):
    """A goal shape the expert planner does not know how to cook."""


@dataclass
class StackDish:
    """A dish stacked on a table: the base item on the table, the items above it, exact placements (``atop``) and
    the item that must end on top."""

    table: int
    base: int
    #: every item variable in the stack above the base, in goal order
    members: list[int] = field(default_factory=list)
    #: atop(A, B): below[A] = B (A must sit directly on B)
    below: dict[int, int] = field(default_factory=dict)
    #: the variable that must end on top (``clear``), if any
    top: int | None = None

    def all_vars(self) -> list[int]:
        """The base and every member: all item variables of the dish."""
        return [self.base] + self.members


@dataclass
class Soup:
    """A soup: water in a bowl, boiled when ``boil``, with items added, and the table the bowl must end on (None: anywhere)."""

    water: int
    bowl: int
    table: int | None
    ingredients: list[int] = field(default_factory=list)
    boil: bool = False


@dataclass
class Recipe:
    """A goal read as cooking work for the planner: the dishes, the soups, and what preparation each item variable needs."""

    dishes: list[StackDish]
    soups: list[Soup]
    #: item variable -> preparation predicates it needs
    needs: dict[int, tuple[str, ...]]
    item_vars: list[int]
    table_vars: list[int]


def analyze(goal: Goal, item_names: set[str], station_names: set[str]) -> Recipe:
    """Group ``goal``'s literals into dishes and soups (UnsupportedGoal if they do not fit)."""
    names = goal.var_names
    handled: set[int] = set()
    lits = list(enumerate(goal.literals))
    needs = _preparations(lits, handled)
    dishes = _dishes(lits, names, station_names, handled)
    soups = _soups(lits, handled)
    missing = [goal.literals[k].predicate for k, _ in lits if k not in handled]
    if missing:
        raise UnsupportedGoal(f"goal literals the planner cannot place: {', '.join(missing)}")
    item_vars = [v for v, n in names.items() if n in item_names]
    table_vars = [d.table for d in dishes.values()] + [s.table for s in soups.values() if s.table is not None]
    return Recipe(
        dishes=list(dishes.values()),
        soups=list(soups.values()),
        needs={v: tuple(ps) for v, ps in needs.items()},
        item_vars=item_vars,
        table_vars=table_vars,
    )


#: the goal's literals with their positions (``handled`` collects the positions each reader places)
_Literals = list[tuple[int, GoalLiteral]]


def _preparations(lits: _Literals, handled: set[int]) -> dict[int, list[str]]:
    """The preparations each item variable needs (cut, cooked, fried); a negative literal is unsupported."""
    needs: dict[int, list[str]] = {}
    for k, lit in lits:
        if not lit.is_true:
            raise UnsupportedGoal(f"negative goal literal {lit.predicate}")
        if lit.predicate in PREP_PREDICATES:
            needs.setdefault(lit.vars[0], []).append(lit.predicate)
            handled.add(k)
    return needs


def _dishes(lits: _Literals, names: dict[int, str], station_names: set[str], handled: set[int]) -> dict[int, StackDish]:
    """The stacked dishes by table variable: the base on its table, the members at it, the ``atop``
    chains, the ``clear`` top."""
    dishes: dict[int, StackDish] = {}
    for k, lit in lits:
        if lit.predicate == "item_on" and names[lit.vars[1]] in station_names:
            item, table = lit.vars
            if table in dishes:
                raise UnsupportedGoal("two items directly on one table")
            dishes[table] = StackDish(table=table, base=item)
            handled.add(k)
    for k, lit in lits:
        if lit.predicate == "item_at" and lit.vars[1] in dishes:
            item, table = lit.vars
            dish = dishes[table]
            if item != dish.base and item not in dish.members:
                dish.members.append(item)
            handled.add(k)
    _hang_atop_chains(lits, dishes, handled)
    for k, lit in lits:
        if lit.predicate == "clear":
            v = lit.vars[0]
            top_of = next((d for d in dishes.values() if v in d.members or v == d.base), None)
            if top_of is None:
                raise UnsupportedGoal("clear() of an item in no dish")
            top_of.top = v
            handled.add(k)
    return dishes


def _hang_atop_chains(lits: _Literals, dishes: dict[int, StackDish], handled: set[int]) -> None:
    """Attach ``atop`` literals to the dish whose base or member they touch, until none is left to attach."""
    changed = True
    while changed:
        changed = False
        for k, lit in lits:
            if lit.predicate != "atop" or k in handled:
                continue
            upper, lower = lit.vars
            dish = next((d for d in dishes.values() if lower in d.all_vars() or upper in d.all_vars()), None)
            if dish is None:
                continue
            for v in (lower, upper):
                if v not in dish.all_vars():
                    dish.members.append(v)
            dish.below[upper] = lower
            handled.add(k)
            changed = True


def _soups(lits: _Literals, handled: set[int]) -> dict[int, Soup]:
    """The soups by water variable: the bowl it goes in, boiling, its ingredients, the bowl's table."""
    soups: dict[int, Soup] = {}
    for k, lit in lits:
        if lit.predicate == "in":
            water, bowl = lit.vars
            soups[water] = Soup(water=water, bowl=bowl, table=None)
            handled.add(k)
    for k, lit in lits:
        if lit.predicate == "isboiling" and lit.vars[0] in soups:
            soups[lit.vars[0]].boil = True
            handled.add(k)
        elif lit.predicate == "addedto" and lit.vars[1] in soups:
            soups[lit.vars[1]].ingredients.append(lit.vars[0])
            handled.add(k)
        elif lit.predicate == "container_at":
            soup = next((s for s in soups.values() if s.bowl == lit.vars[0]), None)
            if soup is not None:
                soup.table = lit.vars[1]
                handled.add(k)
    return soups
