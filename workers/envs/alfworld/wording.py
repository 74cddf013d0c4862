"""The text conventions of ALFWorld game files: command wording per version, banner, goal line.

Game-file versions 2.1.1 and 2.1.2 differ in one command: putting an object down is
``put <obj> in/on <recep>`` in 2.1.1 and ``move <obj> to <recep>`` in 2.1.2 (checked against
both versions' admissible commands; every other verb is spelled the same). The expert
walkthroughs only exist in 2.1.2 wording, and the demonstrations are written in 2.1.1 wording,
so both directions are needed.
"""

from __future__ import annotations

import re

VERSIONS = ("2.1.1", "2.1.2")
DEFAULT_VERSION = "2.1.1"

_MOVE = re.compile(r"^move (.+?) to (.+)$")
_PUT = re.compile(r"^put (.+?) in/on (.+)$")
_BANNER = re.compile(r"^\s*-= Welcome to TextWorld, ALFRED! =-\s*")
_GOAL = re.compile(r"^Your task is to: (.+?)\s*$", re.MULTILINE)


def check_version(version: str) -> str:
    """``version`` itself when it is a known game-file version; ValueError otherwise."""
    if version not in VERSIONS:
        raise ValueError(f"unknown ALFWorld game-file version {version!r}; use one of: {', '.join(VERSIONS)}")
    return version


def to_version(command: str, version: str) -> str:
    """``command`` in the wording of ``version`` (only put/move differ between versions)."""
    if check_version(version) == "2.1.1":
        m = _MOVE.match(command)
        return f"put {m.group(1)} in/on {m.group(2)}" if m else command
    m = _PUT.match(command)
    return f"move {m.group(1)} to {m.group(2)}" if m else command


def strip_banner(text: str) -> str:
    """The game text without TextWorld's welcome banner."""
    return _BANNER.sub("", text, count=1).strip()


def extract_goal(text: str) -> str | None:
    """The task sentence after "Your task is to: ", without its final period."""
    m = _GOAL.search(text)
    return m.group(1).rstrip(".").strip() if m else None
