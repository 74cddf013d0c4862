"""The model's diff as it is handed in: the repository's changes less what a run leaves behind
that no ``git apply`` can apply.

The submission is ``git add -A && git diff --cached <base>`` (the release's
swebench-recap/tools/review_on_submit_m/bin/submit:24, SWE-agent's sweagent/agent/agents.py:856,
mini-swe-agent 1.17's minisweagent/config/extra/swebench.yaml:166). On a repository without a ``.gitignore`` for them, a
command that imported the code (a reproduction script, pytest) leaves ``__pycache__/*.pyc`` files
that ``git add -A`` stages, and ``git diff`` writes each as a binary hunk without data
(``Binary files /dev/null and b/__pycache__/x.pyc differ``). ``git apply`` refuses such a diff
whole ("cannot apply binary patch ... without full index line"); GNU ``patch``, the harness's last
fallback (swebench/harness/run_evaluation.py:64-68 ``GIT_APPLY_CMDS``), skips the binary hunk and
applies the rest. So the same diff was resolved where ``patch`` exists and ``patch_failed`` where it
did not (issue 36 item 3).

OpenHands' SWE-bench inference drops such blocks before it hands the diff to the harness
(All-Hands-AI/OpenHands evaluation/benchmarks/swe_bench/run_infer.py:599-601 calling
``remove_binary_diffs``, evaluation/benchmarks/swe_bench/binary_patch_utils.py:4-32: every
``diff --git`` block with a ``Binary files`` line), and mini-swe-agent 2's SWE-bench prompt tells
the model not to submit "binary or compiled files" (src/minisweagent/config/benchmarks/
swebench.yaml:84-91). :func:`without_build_files` does the former, on the block's header only (a
content line that says "Binary files" is content), and also drops a new file under ``__pycache__``
or named ``*.pyc`` / ``*.pyo`` whatever form git wrote it in: the untracked byte-code a run leaves.
A binary block without data changes nothing wherever it is applied (``git apply`` cannot, ``patch``
skips it), so dropping it leaves the tree the evaluation tests as it was, and ``git apply`` (the
first of the harness's commands, and the only one in an image without ``patch``) now applies the
rest. The review the model sees before it submits shows the diff as it will be handed in.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

#: a path component that holds only byte-code caches (Python's ``__pycache__``)
CACHE_DIRS = ("__pycache__",)
#: the suffixes of Python byte-code files
BYTECODE_SUFFIXES = (".pyc", ".pyo")
_HEADER_NAMES = re.compile(r'^diff --git "?a/(.*?)"? "?b/(.*?)"?$')


@dataclass(frozen=True)
class SubmissionDiff:
    """The diff handed in (``diff``) and the files left out of it (``dropped``: their paths, in order)."""

    diff: str
    dropped: tuple[str, ...] = ()


def is_build_file(path: str) -> bool:
    """Whether ``path`` is Python byte-code a run leaves: under a ``__pycache__`` folder or ``*.pyc`` / ``*.pyo``."""
    parts = path.split("/")
    return any(p in CACHE_DIRS for p in parts[:-1]) or parts[-1].endswith(BYTECODE_SUFFIXES)


def _blocks(diff: str) -> list[list[str]]:
    """``diff``'s lines (newlines kept) cut at each ``diff --git`` line; a preamble is a block of its own."""
    blocks: list[list[str]] = []
    for line in diff.splitlines(keepends=True):
        if line.startswith("diff --git ") or not blocks:
            blocks.append([])
        blocks[-1].append(line)
    return blocks


def _header(block: list[str]) -> list[str]:
    """The block's header lines: up to its first hunk (``@@``) or binary data (``GIT binary patch``)."""
    out = []
    for line in block:
        if line.startswith(("@@", "GIT binary patch")):
            break
        out.append(line.rstrip("\r\n"))
    return out


def _why_dropped(block: list[str]) -> str | None:
    """The block's file when the block is left out (see the module docstring), else None."""
    head = _header(block)
    if not head or not head[0].startswith("diff --git "):
        return None
    m = _HEADER_NAMES.match(head[0])
    path = m.group(2) if m is not None else head[0][len("diff --git ") :]
    if any(line.startswith("Binary files ") and line.endswith(" differ") for line in head[1:]):
        return path
    if any(line.startswith("new file mode ") for line in head[1:]) and is_build_file(path):
        return path
    return None


def without_build_files(diff: str) -> SubmissionDiff:
    """``diff`` (a ``git diff`` output) without its binary blocks that carry no data and without the
    new byte-code files (:func:`is_build_file`), the other blocks byte for byte as they were."""
    kept: list[str] = []
    dropped: list[str] = []
    for block in _blocks(diff):
        path = _why_dropped(block)
        if path is None:
            kept.extend(block)
        else:
            dropped.append(path)
    return SubmissionDiff("".join(kept), tuple(dropped))
