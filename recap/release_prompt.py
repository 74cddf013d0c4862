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
framed as react.py / act.py / chatbot.py:242-253 send it), ``notebook`` (the FEVER notebooks'
own loops, :mod:`recap.baselines.notebook_loop`: ``rounds``, ``final_round`` and
``final_sentence`` for ReAct/Act, ``claim_frame`` for CoT/Standard, all read from the notebook
cells) or ``templated`` (below). Only the release files decide it (:mod:`workers.release.texts`).

Where the released code's own prompt templates are read whole (ReCAP on FEVER:
``fever-recap/MATRIX/MATRIX/chatbot.py``'s ``Prompt`` methods and its reminder, read with
:mod:`ast` by :mod:`workers.release.fever_matrix`), ``first_turn`` is ``templated``: ``templates``
maps a prompt's name to a :meth:`str.format` template with the released placeholders
(:data:`TEMPLATE_NAMES`), ``empty_list`` holds the text a template shows for an empty
subtask list, the root's task is the environment's first observation and ``first_observation``
the text the released runner shows as the initial observation (hotpotqa_simulator.py:26).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

#: the prompts a ``templated`` release gives, and the placeholders each may hold: ``task``
#: (task_name, init_obs, rule, system_prompt), ``descend`` (task_name), ``leaf_done`` / ``leaf_judge``
#: / ``leaf_fail`` (obs, done_task_name or fail_task_name, previous_stage_task_name,
#: previous_stage_think, remaining_subtask_str), ``nonleaf_done`` / ``nonleaf_judge`` (the same
#: without obs), ``reminder`` (rule; put before the prompt), ``final_answer`` (none), ``demo``
#: (few_shot_str), ``json_error`` (none: a reply that is not JSON), ``error`` (e: another error)
TEMPLATE_NAMES = (
    "task",
    "descend",
    "leaf_done",
    "leaf_judge",
    "leaf_fail",
    "nonleaf_done",
    "nonleaf_judge",
    "reminder",
    "final_answer",
    "demo",
    "json_error",
    "error",
)


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
    first_turn: Literal["labelled", "framed", "notebook", "templated"] = "labelled"
    #: the notebook loop's rounds (``range(1, rounds + 1)``), the round that gets
    #: ``final_sentence`` before its label (ReAct/Act; None elsewhere)
    rounds: int | None = None
    final_round: int | None = None
    final_sentence: str | None = None
    #: the one prompt's text before and after the question (CoT/Standard notebooks)
    claim_frame: tuple[str, str] | None = None
    templates: tuple[tuple[str, str], ...] = ()
    #: per template name: the text it shows for an empty remaining-subtask list
    empty_list: tuple[tuple[str, str], ...] = ()
    first_observation: str | None = None

    def template(self, name: str) -> str:
        """The ``templated`` release's template ``name``; KeyError when it has none."""
        return dict(self.templates)[name]

    def render(self, name: str, **values: str) -> str:
        """Template ``name`` with ``values`` filled in (placeholders it does not hold are ignored)."""
        return self.template(name).format(**values)

    def __post_init__(self) -> None:
        for name, _ in self.templates:
            if name not in TEMPLATE_NAMES:
                raise ValueError(f"unknown release template {name!r}")
        for role, content in (*self.messages, *self.planner, *self.executor):
            if role not in ("system", "user", "assistant") or not isinstance(content, str):
                raise ValueError(f"a release message needs a role system/user/assistant and text, got {role!r}")
