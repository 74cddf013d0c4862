"""The gold patch as tool calls, for the offline expert model (a test double) and solvability checks.

:func:`parse_patch` reads a unified git diff into files and hunks; :func:`replacements` turns one
file's hunks into ``str_replace`` pairs whose ``old_str`` occurs exactly once in the file at the
moment it is applied (the hunk's lines, widened by whole lines around it until unique), so playing
them in order rebuilds the gold file. :mod:`.env` decides which of them are still to play.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

_HUNK = re.compile(r"^@@ -(\d+)(?:,(\d+))? \+(\d+)(?:,(\d+))? @@")


@dataclass
class Hunk:
    """One ``@@`` block: where it starts in the old file and its old and new lines (with their ends)."""

    old_start: int
    old_lines: list[str] = field(default_factory=list)
    new_lines: list[str] = field(default_factory=list)


@dataclass
class FilePatch:
    """The hunks of one file; ``old_path``/``new_path`` None for a file created/deleted."""

    old_path: str | None
    new_path: str | None
    hunks: list[Hunk] = field(default_factory=list)
    binary: bool = False

    @property
    def path(self) -> str:
        """The file's path in the repository (the new one unless it is deleted)."""
        p = self.new_path if self.new_path is not None else self.old_path
        assert p is not None
        return p


def _side_path(line: str, prefix: str) -> str | None:
    name = line[4:].rstrip("\n").split("\t", 1)[0]
    if name == "/dev/null":
        return None
    return name[len(prefix) :] if name.startswith(prefix) else name


def parse_patch(patch: str) -> list[FilePatch]:
    """The files of a unified git diff, in order; hunk bodies end where their header's counts say."""
    files: list[FilePatch] = []
    lines = patch.splitlines(keepends=True)
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.startswith("diff --git "):
            m = re.match(r"^diff --git a/(.+?) b/(.+?)\n?$", line)
            files.append(FilePatch(m.group(1) if m else None, m.group(2) if m else None))
        elif line.startswith("Binary files ") or line.startswith("GIT binary patch"):
            if files:
                files[-1].binary = True
        elif line.startswith("--- ") and files and not files[-1].hunks:
            files[-1].old_path = _side_path(line, "a/")
        elif line.startswith("+++ ") and files and not files[-1].hunks:
            files[-1].new_path = _side_path(line, "b/")
        elif (m := _HUNK.match(line)) and files:
            old_n = int(m.group(2)) if m.group(2) is not None else 1
            new_n = int(m.group(4)) if m.group(4) is not None else 1
            hunk = Hunk(int(m.group(1)))
            i += 1
            last = ""
            while i < len(lines) and (len(hunk.old_lines) < old_n or len(hunk.new_lines) < new_n or lines[i].startswith("\\")):
                body = lines[i]
                tag, text = body[:1], body[1:]
                if tag == "\\":  # "\ No newline at end of file": the line before has no line end
                    if last in (" ", "-") and hunk.old_lines:
                        hunk.old_lines[-1] = hunk.old_lines[-1].rstrip("\n")
                    if last in (" ", "+") and hunk.new_lines:
                        hunk.new_lines[-1] = hunk.new_lines[-1].rstrip("\n")
                elif tag in (" ", "\n"):
                    text = text if tag == " " else "\n"
                    hunk.old_lines.append(text)
                    hunk.new_lines.append(text)
                elif tag == "-":
                    hunk.old_lines.append(text)
                elif tag == "+":
                    hunk.new_lines.append(text)
                else:
                    break
                last = tag if tag != "\n" else " "
                i += 1
            files[-1].hunks.append(hunk)
            continue
        i += 1
    return files


def _occurs_once(haystack: str, needle: str) -> bool:
    first = haystack.find(needle)
    return first != -1 and haystack.find(needle, first + 1) == -1


def replacements(base: str, hunks: list[Hunk]) -> tuple[list[tuple[str, str]], str]:
    """``(old_str, new_str)`` pairs that turn ``base`` into the patched file, each ``old_str``
    unique when applied, and the patched text; ValueError when a hunk does not match ``base``."""
    cur = base.splitlines(keepends=True)
    pairs: list[tuple[str, str]] = []
    delta = 0
    for h in hunks:
        n = len(h.old_lines)
        p = (h.old_start - 1 if n else h.old_start) + delta
        if cur[p : p + n] != h.old_lines:
            raise ValueError(f"a hunk at old line {h.old_start} does not match the file")
        a, b = p, p + n
        text = "".join(cur)
        while not (a < b and _occurs_once(text, "".join(cur[a:b]))):
            if a == 0 and b == len(cur):
                break
            if b < len(cur):
                b += 1
            if a > 0 and not (a < b and _occurs_once(text, "".join(cur[a:b]))):
                a -= 1
        old = "".join(cur[a:b])
        new_block = cur[a:p] + h.new_lines + cur[p + n : b]
        pairs.append((old, "".join(new_block)))
        cur = cur[:a] + new_block + cur[b:]
        delta += len(h.new_lines) - n
    return pairs, "".join(cur)
