"""Robotouille environment description, rules and failure hints, in this project's own words.

The prompts of every agent embed ``rules_text(split)``; it carries what an agent needs to know
about the kitchen that the observation does not say: the kinds of objects, what the robot can
hold, where actions happen, how stacking works, that cutting takes three cuts, that cooking,
frying and boiling finish three steps after they start (asynchronous kitchens), and how the
dishes of the benchmark are assembled. ``failure_hints`` is shown after a rejected action.
"""

from __future__ import annotations

_DESCRIPTION = """\
You control a robot in a kitchen. The observation lists every object in the kitchen with what is
currently true about it, then the actions you may take right now, then your goal.
The kitchen holds five kinds of objects:
- Station: a fixed place where things can be put and worked on (table, cutting board, stove, fryer, sink).
- Item: an ingredient or a piece of bread/bun; the robot can carry it and put it on a station.
- Player: a robot; you are one of them.
- Container: a pot or a bowl, which can hold a meal.
- Meal: a liquid mixture (such as water with ingredients) inside a container."""

_RULES = """\
Rules of this kitchen:
- The robot carries at most one item or container at a time; put it down before picking up another.
- An item can only be cut, cooked or fried while it sits on the matching station (a cutting board,
  a stove, a fryer), directly on the station, with nothing on top of it, and the robot at that station.
- A station holding one thing is occupied: putting an item down there stacks it on top of what is
  already there. Items go only on top of a stack, never underneath; to reach a lower item, take the
  items above it off first (unstack), one at a time, and put them somewhere else.
- Only the top item of a stack can be picked up.
- An item must be cut three times, one Cut action after another, before it counts as cut.
- Ingredients can only be added to a pot that already contains a meal (fill the pot with water at a
  sink first); the contents of a pot can then be poured into a bowl.
- Use the action strings exactly as they are listed under Valid Actions."""

_TIMING_SYNC = """\
- Every action takes effect immediately, except cutting (three cuts) and, if you use them, cooking,
  frying, boiling and filling a pot, which finish three steps after the step that started them."""

_TIMING_ASYNC = """\
- Cooking (stove), frying (fryer), filling a pot with water (sink) and boiling a pot (stove) are
  started by one action and finish three steps later; the item or pot must stay where it is until
  then (taking it away pauses the timer). You may do other useful work in the meantime.
- If there is truly nothing else useful to do while waiting, take the Do nothing action once for each
  step still needed."""

_RECIPES = """\
How the dishes are made:
- Sandwich: on an empty table, a slice of bread directly on the table, the prepared ingredients
  stacked on it, and another slice of bread on top.
- Hamburger: on an empty table, a bottom bun directly on the table, the prepared ingredients stacked
  on it, and a top bun on top.
- Soup: fill a pot with water at a sink, boil it on a stove, add the ingredients to the pot, then pour
  the soup into a bowl that stands where the goal wants it."""


def rules_text(split: str) -> str:
    """Description + rules + recipe guide for a ``synchronous`` or ``asynchronous`` kitchen."""
    timing = _TIMING_ASYNC if split.startswith("asynchronous") else _TIMING_SYNC
    return f"{_DESCRIPTION}\n\n{_RULES}\n{timing}\n\n{_RECIPES}"


_HINTS = """\
The last action was rejected. Common causes:
- The action text must match one of the Valid Actions exactly (same object numbers, same words).
- A station that already holds something is occupied: you can only stack on top of it, or first
  move what is there to another station.
- An item with something stacked on it cannot be cut, cooked or fried; unstack the items above it first.
- An item underneath another cannot be picked up; take the items above it off first."""


def failure_hints() -> str:
    """The hints shown after a rejected action (the same for both splits)."""
    return _HINTS
