"""FEVER's rules text for the prompts, in our own words, carrying the paper's FEVER rules.

The paper's rules prompt for FEVER (appendix "FEVER" of the prompts, and the released
``fever-recap/conf/config.toml:6-35``) says: the task is to verify a claim by alternating
reasoning and actions; the three actions and what each returns (a page's opening or similar
titles, the next sentence holding a string, the verdict that ends the task); the three verdict
labels, exactly as written; and to give the verdict only once no further search or lookup could
change it. Every method sees the same text (the paper keeps rules identical across agents);
CoT and Standard, which give only a verdict (the paper: "for Standard/CoT we prompt only the
final verdict"), see the same facts with the one-action plan they may write.
"""

from __future__ import annotations

_TASK = """\
Your task is to decide whether a claim is true according to Wikipedia. The first observation
gives the claim ("Claim: ...")."""

_ACTIONS = """\
You work by alternating reasoning about what you know and still need to check with actions.
Each action is one of:
1. search[entity]: opens the Wikipedia page of exactly that entity and shows its first five
   sentences; when no page has that title, it lists up to five similar titles you can search
   for instead. Search for named things or concepts that are likely to have a page of their own.
2. lookup[keyword]: shows the next sentence of the page you opened last that contains the
   keyword; calling it again with the same keyword shows the following one. Keep the keyword
   short and specific.
3. finish[verdict]: ends the task with your verdict."""

_VERDICTS = """\
The verdict is exactly one of three labels, written as shown, with nothing else inside the
brackets: finish[SUPPORTS] when the evidence confirms the claim, finish[REFUTES] when the
evidence contradicts it, finish[NOT ENOUGH INFO] when it does neither or nothing relevant can be
found."""

_WHEN = """\
Give the verdict only when you are sure that no further search or lookup could change it; while
the claim still needs evidence, search or look up more. At most {max_steps} actions: every
action counts, a malformed one too, and the episode ends at the cap without a verdict."""

_VERDICT_ONLY = """\
Here you cannot search: give your verdict from what you know, as a plan of exactly one action,
finish[SUPPORTS], finish[REFUTES] or finish[NOT ENOUGH INFO]."""


def rules_text(max_steps: int, *, verdict_only: bool = False) -> str:
    """The FEVER rules with the action cap ``max_steps``; ``verdict_only`` for methods that give
    the verdict alone (CoT, Standard)."""
    if verdict_only:
        return "\n\n".join((_TASK, _VERDICTS, _VERDICT_ONLY))
    return "\n\n".join((_TASK, _ACTIONS, _VERDICTS, _WHEN.format(max_steps=max_steps)))
