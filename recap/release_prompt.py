"""The authors' released prompt for one episode (``prompts: release``), as plain strings.

workers/ reads the release files at run time (:mod:`workers.release.texts`) and hands the agent
this object; recap/ reads no file. ``messages`` are what the released code sends before the
episode's first observation, each with its role, in order (for the Robotouille baselines: the
prompt file's system text, its instructions as a user message, then each in-context example as
separate user/assistant messages: ``robotouille-baselines/agents/prompt_builder/serializer.py:53-57``,
``agents/in_context_examples/retrieve_example.py:27-37``). The agent pins them in place of our
demonstration and then sends its first turn *without* our system text and rules (the release's
text carries those); the turn framing is the agent's, built in the released structure.

Where the released method talks in several contexts of its own (ADaPT on Robotouille: a planner
and one executor per subtask, ``robotouille-baselines/agents/ADaPT_agent.py:37-61, 237-243``),
``messages`` is empty (nothing goes in the episode's main context) and ``planner``/``executor``
carry each context's pinned messages.

Where the released code puts the template's text into the first *turn* instead of messages of
its own (ReCAP: ``robotouille-recap/MATRIX/MATRIX/chatbot.py:247-261`` builds the first prompt
from the YAML's system text and rules), ``system`` and ``rules`` carry that text and the agent
frames it (and re-sends ``rules`` in its reminders).

``first_turn`` says whose released code the agent's first turn follows, so an agent never asks
which benchmark it plays: ``labelled`` (Robotouille's releases: the observation, or ReCAP's
template-framed task) or ``framed`` (the ALFWorld release: the environment's rule and the task
framed as react.py / act.py / chatbot.py:242-253 send it) or ``notebook`` (the FEVER notebooks'
own loops, :mod:`recap.baselines.notebook_loop`: ``rounds``, ``final_round`` and
``final_sentence`` for ReAct/Act, ``claim_frame`` for CoT/Standard, all read from the notebook
cells). Only the release files decide it (:mod:`workers.release.texts`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal


@dataclass(frozen=True)
class ReleasePrompt:
    """``messages``: (role, content) pairs pinned first, in order (roles ``system``, ``user``,
    ``assistant``); ``system``/``rules``: the released text the agent's first turn carries in
    place of ours (None: the method's release has none of its own, as for the baselines);
    ``planner``/``executor``: the messages pinned first in those contexts of a method that opens
    its own (ADaPT; empty otherwise)."""

    messages: tuple[tuple[str, str], ...]
    system: str | None = None
    rules: str | None = None
    planner: tuple[tuple[str, str], ...] = ()
    executor: tuple[tuple[str, str], ...] = ()
    first_turn: Literal["labelled", "framed", "notebook"] = "labelled"
    #: the notebook loop's rounds (``range(1, rounds + 1)``), the round that gets
    #: ``final_sentence`` before its label (ReAct/Act; None elsewhere)
    rounds: int | None = None
    final_round: int | None = None
    final_sentence: str | None = None
    #: the one prompt's text before and after the question (CoT/Standard notebooks)
    claim_frame: tuple[str, str] | None = None

    def __post_init__(self) -> None:
        for role, content in (*self.messages, *self.planner, *self.executor):
            if role not in ("system", "user", "assistant") or not isinstance(content, str):
                raise ValueError(f"a release message needs a role system/user/assistant and text, got {role!r}")
