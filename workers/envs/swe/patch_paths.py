"""Whether a patch stays inside the repository it is applied to, decided on its text before any
``git apply`` or ``patch`` runs.

A patch names the files it writes in its headers (``diff --git a/X b/Y``, ``--- X``, ``+++ Y``,
``rename from``/``to``, ``copy from``/``to``, ``Index:``, a context diff's ``*** X``). git apply
refuses some escapes on its own and GNU ``patch`` (the SWE-bench harness's last fallback,
``GIT_APPLY_CMDS``) others, each in its own way and version, and a refusal there reads as "the
patch does not apply". Here one rule, ours, is checked first (:func:`patch_refusal`): every name
relative (``/dev/null`` aside), no ``..`` component, no empty component, no ``.git`` component
(any case: the repository's own metadata, hooks included), and a symlink a patch creates
(``new file mode 120000``) pointing inside the repository, neither absolute nor through ``..``
out of it nor into ``.git``.

Lines inside a hunk are content, not headers: a unified hunk is consumed by its ``@@ -a,b +c,d @@``
counts, so a removed line that reads ``--- ../x`` is not taken for a header; anything the counts do
not account for is read as a header again (the stricter reading). Quoted names (git writes
``"a/\\303\\251"`` for unusual bytes) are checked both as written and with their escapes decoded.

Where it is used: a gold ``patch`` or ``test_patch`` of a user's instances file, or of a SWE-bench
Verified record, is refused at load (:mod:`.instances`, :mod:`workers.envs.swe_verified.dataset`);
a model's diff is refused by the evaluation before it is applied (:mod:`.evaluate`: reason
``patch_refused``, the model's failure, not the infrastructure's).
"""

from __future__ import annotations

import posixpath
import re

#: the mode git writes for a symbolic link
SYMLINK_MODE = "120000"
_HUNK = re.compile(r"^@@ -\d+(?:,(\d+))? \+\d+(?:,(\d+))? @@")
#: header lines that name a file, with the prefix to drop before the names
_NAMING = ("diff --git ", "--- ", "+++ ", "*** ", "rename from ", "rename to ", "copy from ", "copy to ", "Index: ")
_ESCAPE = re.compile(r"\\([0-7]{1,3}|.)")
_SIMPLE = {"a": "\a", "b": "\b", "t": "\t", "n": "\n", "v": "\v", "f": "\f", "r": "\r", '"': '"', "\\": "\\"}


def _unescape(text: str) -> str:
    """``text`` with git's C-style escapes decoded (octal bytes as UTF-8, the rest as git writes them)."""

    def one(m: re.Match[str]) -> str:
        code = m.group(1)
        if code[0] in "01234567":
            return chr(int(code, 8) & 0xFF)
        return _SIMPLE.get(code, code)

    decoded = _ESCAPE.sub(one, text)
    try:
        return decoded.encode("latin-1").decode("utf-8")
    except (UnicodeEncodeError, UnicodeDecodeError):
        return decoded


def _name_problem(name: str) -> str | None:
    """Why one path-like token leaves the repository, or None."""
    if name == "/dev/null":
        return None
    if name.startswith("/"):
        return f"the absolute path {name!r}"
    parts = name.split("/")
    if ".." in parts:
        return f"{name!r} (a '..' component)"
    if any(p.lower() == ".git" for p in parts):
        return f"{name!r} (inside .git)"
    if "" in parts[:-1]:
        return f"{name!r} (an empty path component)"
    return None


def names_problem(text: str) -> str | None:
    """Why the names in a header's text (after its keyword) leave the repository, or None; every
    whitespace- or quote-separated token is checked, as written and with escapes decoded."""
    for variant in (text, _unescape(text)) if "\\" in text else (text,):
        for token in re.split(r'[\s"]+', variant):
            if token and (problem := _name_problem(token)) is not None:
                return problem
    return None


def _symlink_problem(link: str, target: str) -> str | None:
    """Why a symlink ``link`` -> ``target`` the patch creates points outside the repository, or None."""
    if not target or target.startswith("/"):
        return f"creates the symlink {link!r} to {target!r}, outside the repository"
    resolved = posixpath.normpath(posixpath.join(posixpath.dirname(link), target))
    parts = resolved.split("/")
    if parts[0] == ".." or any(p.lower() == ".git" for p in parts):
        return f"creates the symlink {link!r} to {target!r}, outside the repository"
    return None


def patch_refusal(patch: str) -> str | None:
    """Why ``patch`` would write outside the repository it is applied to (one line: the first
    offending name), or None when every file it names stays inside (see the module docstring)."""
    old = new = 0  # lines left in the current unified hunk
    current: str | None = None  # the file of the current ``diff --git`` block
    symlink_pending = False  # a symlink is created; its target is the next hunk's first '+' line
    for number, line in enumerate(patch.split("\n"), 1):  # git and patch split on newlines only
        line = line.removesuffix("\r")
        if old > 0 or new > 0:
            head = line[:1]
            if head in ("", " "):
                old, new = old - 1, new - 1
                continue
            if head == "-":
                old -= 1
                continue
            if head == "+":
                if symlink_pending and current is not None:
                    symlink_pending = False
                    if (problem := _symlink_problem(current, line[1:])) is not None:
                        return f"line {number} of the patch {problem}"
                new -= 1
                continue
            if head == "\\":
                continue
            old = new = 0  # the counts did not hold: read the line as a header
        m = _HUNK.match(line)
        if m is not None:
            old = int(m.group(1)) if m.group(1) is not None else 1
            new = int(m.group(2)) if m.group(2) is not None else 1
            continue
        if line.startswith(("new file mode ", "new mode ")) and line.split()[-1] == SYMLINK_MODE:
            symlink_pending = True
            continue
        for prefix in _NAMING:
            if line.startswith(prefix):
                rest = line[len(prefix) :]
                if prefix in ("--- ", "+++ ", "*** "):
                    rest = rest.split("\t", 1)[0]  # a date after a tab
                if (problem := names_problem(rest)) is not None:
                    return f"line {number} of the patch names {problem}, outside the repository"
                if prefix == "diff --git ":
                    current = _b_name(rest)
                    symlink_pending = False
                break
    return None


def _b_name(rest: str) -> str | None:
    """The ``b/`` name of a ``diff --git a/X b/Y`` line (without the prefix), or None when unclear."""
    m = re.match(r'^"?a/.*?"? "?b/(.*?)"?$', rest)
    return _unescape(m.group(1)) if m is not None else None
