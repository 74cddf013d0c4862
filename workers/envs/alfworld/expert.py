"""The offline expert for ALFWorld: a game's stored walkthrough, consumed as it is played.

ALFWorld 2.1.2 game files carry a winning command list. The expert's plan from the current state
is the part of that list not yet executed: the index advances only when the executed action
equals the next walkthrough action, so an agent that follows the plan always sees the correct
remainder (an agent that wanders off is shown the rest of the original route, which the offline
test model only uses while it follows it).
"""

from __future__ import annotations

from collections.abc import Sequence

from workers.envs.alfworld.wording import to_version


class WalkthroughExpert:
    """The walkthrough of one game as an expert: the winning commands (in the game version's wording) not yet executed."""

    def __init__(self, walkthrough: Sequence[str], version: str):
        self.plan = tuple(to_version(a, version) for a in walkthrough)
        self._next = 0

    def reset(self) -> None:
        """Start the walkthrough over (a new episode of the same game)."""
        self._next = 0

    def observe(self, action: str) -> None:
        """Advance past the next walkthrough command when ``action`` is that command; any other action leaves the
        plan where it was."""
        if self._next < len(self.plan) and action == self.plan[self._next]:
            self._next += 1

    def remaining(self) -> list[str]:
        """The walkthrough commands not yet executed, in order."""
        return list(self.plan[self._next :])
