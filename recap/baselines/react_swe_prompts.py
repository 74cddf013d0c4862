"""The prompts of ReAct as mini-SWE-agent runs it on SWE-bench, in our own words.

What each carries follows mini-SWE-agent's SWE-bench configuration (the paper's ReAct baseline on
SWE-bench, section "Baselines"): the system text asks for a THOUGHT and exactly one bash block with
one command per reply; the task text gives the issue, the recommended way to work, the rules and
how to submit (the sentinel command, alone); each observation shows the command's return code and
output (long output: its head and tail with a warning); a reply with no or several bash blocks is
answered with a format error. The sentences are ours.
"""

from __future__ import annotations

#: mini-SWE-agent's submit line (workers/envs/swe: the command whose output starts with it submits)
SUBMIT_SENTINEL = "COMPLETE_TASK_AND_SUBMIT_FINAL_OUTPUT"
#: the command that submits
SUBMIT_COMMAND = f"echo {SUBMIT_SENTINEL}"
#: output longer than this is shown as its head and tail (mini-SWE-agent's 10,000 characters)
MAX_OUTPUT_CHARS = 10_000
#: how much of the head and of the tail a long output shows
SHOWN_CHARS = 5_000

REPLY_FORMAT = "THOUGHT: <your reasoning>\n\n```bash\n<exactly one command>\n```"


def system_text() -> str:
    """How to reply: a THOUGHT, then exactly one bash block with one command."""
    return (
        "You are an assistant that solves programming tasks by working in a computer shell over "
        "several turns. Every reply must start with a THOUGHT section that explains your reasoning, "
        "followed by exactly one bash code block holding exactly one command (commands joined with "
        "&& or || count as one). A reply with no bash block, or with more than one, is rejected.\n\n"
        f"The form of every reply:\n{REPLY_FORMAT}"
    )


def task_prompt(*, rules: str, issue: str, goal: str) -> str:
    """The pinned first prompt: the system text, the environment, the issue, the goal, how to work
    and how to submit (no demonstration: none is used on SWE-bench)."""
    return "\n\n".join(
        [
            system_text(),
            f"The environment:\n{rules}",
            f"The issue:\n{issue}",
            f"Your task: {goal}",
            "A good way to work: find and read the code the issue concerns; write a small script that "
            "reproduces the problem and run it; change the source code to fix it; run the script "
            "again to confirm the fix; think about edge cases and check them too.",
            "Rules: each reply runs one command in a fresh shell (a `cd` does not carry over to the "
            "next reply); interactive programs (editors, pagers) do not work; edit files with "
            "commands such as `sed -i` or a small Python script; do not change the tests.",
            f"When you are done and have checked your change, submit it by running exactly this "
            f"command on its own:\n```bash\n{SUBMIT_COMMAND}\n```\nAfter that you cannot continue.",
        ]
    )


def observation_prompt(output: str, returncode: int | None) -> str:
    """A command's result: its return code and its output, the middle left out of a long one."""
    code = "" if returncode is None else f"<returncode>{returncode}</returncode>\n"
    if len(output) <= MAX_OUTPUT_CHARS:
        return f"{code}<output>\n{output}\n</output>"
    left = len(output) - 2 * SHOWN_CHARS
    return (
        f"{code}<warning>The output was too long: its first and last {SHOWN_CHARS} characters are shown "
        f"and {left} in between are left out. Use a command that prints less (grep, head, tail, sed -n).</warning>\n"
        f"<output_head>\n{output[:SHOWN_CHARS]}\n</output_head>\n"
        f"<elided_chars>{left}</elided_chars>\n"
        f"<output_tail>\n{output[-SHOWN_CHARS:]}\n</output_tail>"
    )


def format_error_prompt(blocks: int) -> str:
    """After a reply with no or several bash blocks: what was wrong and the form to use."""
    return (
        f"Your reply had {blocks} bash code blocks; it must have exactly one. Write a THOUGHT "
        f"section, then exactly one bash block with one command:\n{REPLY_FORMAT}\n"
        f"To submit when you are done, the command is `{SUBMIT_COMMAND}` on its own."
    )
