"""What the model is told on SWE-bench, in our own words: the rules, the goal, the review on submit.

What each text carries follows the release (swebench-recap/config/recap.yaml): the instance text
names the repository folder, says the tests are already taken care of and must not be changed, and
asks for the smallest change to non-test files (:8-27); the review message asks to re-run the
reproduction, remove it, revert test files, then submit again, and shows the diff (:122-138).
"""

from __future__ import annotations

from workers.sandbox.base import SandboxLimits


def goal_text(workdir: str) -> str:
    """The episode's goal: resolve the issue by changing the repository."""
    return f"Change the code in the repository at {workdir} so that the issue described above is resolved."


#: the rules' line on the network, as the sandbox has it (on in the ReCAP release's container,
#: workers/envs/swe_verified/release_container.py, or where a sweep turns it on)
NETWORK_OFF = "- There is no network access: nothing can be installed or downloaded."
NETWORK_ON = "- The network is on: packages can be installed and files downloaded."


def rules_text(workdir: str, limits: SandboxLimits, total_output_bytes: int, sentinel: str) -> str:
    """The environment's rules: the repository, the tools, the limits, the network, tests left alone."""
    return (
        f"You work in a Python code repository checked out at {workdir}. The task is a real issue report "
        "(shown as the first observation); change the repository so the issue is resolved.\n"
        "\n"
        "Tools:\n"
        f"- bash: run one shell command in {workdir}.\n"
        "- view: show a file with line numbers, or list a folder two levels deep.\n"
        "- str_replace: replace text that occurs exactly once in a file.\n"
        "- create: write a new file.\n"
        "- insert: insert lines after a given line of a file.\n"
        "- undo_edit: undo your last change to a file made with str_replace, insert or create.\n"
        "- submit: hand in your changes. The first call shows your diff for a last review; call it again to finish.\n"
        "If you act with plain text instead of tool calls, each action is one bash command, and the command "
        f"`echo {sentinel}` hands in your changes at once.\n"
        "\n"
        "Rules:\n"
        "- The tests that will judge your change are already written and kept apart from you: do not add, "
        "change or delete test files. Change only what the issue needs, in the non-test code.\n"
        "- A good way to work: read the code the issue concerns, write a small script that reproduces the "
        "problem and run it, fix the code, run the script again, think about edge cases, remove the script.\n"
        f"{NETWORK_ON if limits.network else NETWORK_OFF}\n"
        f"- Each command is stopped after {limits.command_timeout_s:g} seconds and shows at most "
        f"{limits.output_bytes} bytes of output. The episode allows {limits.max_commands} tool calls, "
        f"{limits.wall_time_s:g} seconds of command time and {total_output_bytes} bytes of output in all; "
        "when one runs out, your changes as they stand are submitted.\n"
        "- Interactive programs (editors, pagers, a Python prompt) do not work: every command must finish on its own."
    )


def review_text(diff: str) -> str:
    """The first submit's answer: the review steps, then the current diff."""
    return (
        "Before your changes are final, please review them:\n"
        "1. If you changed the code after you last ran your reproduction script, run it again; if it fails, "
        "go back and fix the code. (If you already removed the script, skip this.)\n"
        "2. Delete the reproduction script and any other scratch files you created.\n"
        "3. If you changed any test file, restore it as it was (for example `git checkout -- path/to/test_file.py`); "
        "the diff below shows which files you changed.\n"
        "4. Then call submit again to hand in your changes.\n"
        "\n"
        "Your changes so far:\n"
        "<diff>\n"
        f"{diff.rstrip()}\n"
        "</diff>"
    )
