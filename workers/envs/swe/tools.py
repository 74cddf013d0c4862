"""The tools a coding model calls, and how each runs against a :class:`~workers.sandbox.base.Sandbox`.

The set follows what SWE-agent gives the paper's ReCAP runs (swebench-recap/config/recap.yaml:116-119 and 139:
the bash tool, ``tools/edit_anthropic`` and ``tools/review_on_submit_m``): one ``bash`` command
per call, in one bash session per episode (:mod:`workers.sandbox.session`); the editor split into ``view`` (a file as ``cat -n`` shows it, a folder two levels deep,
tools/edit_anthropic/config.yaml:10), ``str_replace`` (``old_str`` must occur exactly once, :16-17)
``create`` (never over an existing file, :11), ``insert`` (after a line, 0 for the top) and
``undo_edit`` (the editor's last change to a file undone, :13; a created file is removed, where
the release's editor keeps it); and ``submit`` without arguments (the review
step lives in the environment, :mod:`.env`). Descriptions are our own words and state the limits.

A refused call (unknown tool, an argument missing, unknown or of the wrong type, a path outside the
repository, ``old_str`` found zero or several times) is an observation that says why plus
``info["error"]``; nothing here raises for what a model wrote (issue 35 item 5): a path that leaves
the repository through a symbolic link (the sandbox resolves it inside, :class:`OutsideRepository`),
a dangling link, a NUL byte, a path too long, a fifo or a device, a file without read permission,
text that is not Unicode, a file too large for the editor - each is a refusal naming the path, and
the episode goes on. A broken sandbox raises :class:`~workers.sandbox.base.SandboxError`.

Bounded reads (issue 35 item 4): ``view`` asks the sandbox for the lines it shows, at most the
output cap (:meth:`~workers.sandbox.base.Sandbox.read_lines`), never the whole file; the editor's
changes need the whole file, read only up to :data:`EDIT_MAX_BYTES` (a larger file is refused:
"too large for the editor; use bash").
"""

from __future__ import annotations

import errno
import posixpath
import shlex
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from recap.llm import ToolDef
from workers.sandbox.base import CommandResult, FileTooLarge, OutsideRepository, Sandbox, SandboxLimits
from workers.sandbox.session import ShellSession

BASH = "bash"
VIEW = "view"
STR_REPLACE = "str_replace"
CREATE = "create"
INSERT = "insert"
UNDO_EDIT = "undo_edit"
SUBMIT = "submit"
TOOL_NAMES = (BASH, VIEW, STR_REPLACE, CREATE, INSERT, UNDO_EDIT, SUBMIT)
#: lines shown around an edit so the model sees its result
SNIPPET_LINES = 4
#: the largest file str_replace, insert and undo_edit read whole into the worker (bytes); larger
#: files are refused ("too large for the editor; use bash"): source files are far smaller
EDIT_MAX_BYTES = 4_000_000
#: the longest path a tool takes (bytes; Linux's PATH_MAX)
PATH_MAX_BYTES = 4096
#: the longest command the bash tool runs (bytes): one argument of a process may hold 128 KiB
#: (MAX_ARG_STRLEN), and the sandbox wraps the command; longer scripts go into a file first
COMMAND_MAX_BYTES = 64 * 1024


def tool_defs(workdir: str, limits: SandboxLimits) -> tuple[ToolDef, ...]:
    """The five tools, their descriptions naming the repository folder and the limits."""
    path_arg = {
        "type": "string",
        "description": f"A path inside the repository: absolute (under {workdir}) or relative to {workdir}.",
    }
    cap = limits.output_bytes
    return (
        ToolDef(
            BASH,
            f"Run a shell command in one bash session kept for the whole task: it starts in {workdir}, and the working "
            "directory, variables (exported or not), functions and aliases carry over from one call to the next; "
            "background processes do not (whatever a command started is stopped when it returns). "
            f"A command is stopped after {limits.command_timeout_s:g} seconds, and the session then goes on as it was "
            f"before that command. The model sees at most {cap} bytes of its combined stdout and stderr; longer output "
            f"is cut and the cut is said. {'The network is on.' if limits.network else 'No network.'} "
            "Do not start interactive programs (editors, pagers, a Python prompt).",
            {
                "type": "object",
                "properties": {"command": {"type": "string", "description": "The command line to run."}},
                "required": ["command"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            VIEW,
            "Show a file with numbered lines (as `cat -n` prints it), or, for a folder, the files and folders in it "
            f"up to two levels down (hidden ones left out). Output past {cap} bytes is cut.",
            {
                "type": "object",
                "properties": {
                    "path": path_arg,
                    "view_range": {
                        "type": "array",
                        "items": {"type": "integer"},
                        "minItems": 2,
                        "maxItems": 2,
                        "description": "Files only: [first, last] line to show, counting from 1; last -1 means to the end.",
                    },
                },
                "required": ["path"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            STR_REPLACE,
            "Replace text in a file: `old_str` must appear in the file exactly once, character for character "
            "(whitespace and indentation included), and is replaced by `new_str`. When it appears several times, "
            "add surrounding lines until it is unique. The edited region is shown afterwards.",
            {
                "type": "object",
                "properties": {
                    "path": path_arg,
                    "old_str": {
                        "type": "string",
                        "description": "The exact text to replace (one or more whole lines is safest).",
                    },
                    "new_str": {
                        "type": "string",
                        "description": "The replacement text; leave it out or empty to delete old_str.",
                    },
                },
                "required": ["path", "old_str"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            CREATE,
            "Create a new file with the given text (its folders are made). Refused when the path already exists; "
            "use str_replace to change an existing file.",
            {
                "type": "object",
                "properties": {
                    "path": path_arg,
                    "file_text": {"type": "string", "description": "The whole content of the new file."},
                },
                "required": ["path", "file_text"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            INSERT,
            "Insert text into a file after a given line (0: at the top). The edited region is shown afterwards.",
            {
                "type": "object",
                "properties": {
                    "path": path_arg,
                    "insert_line": {
                        "type": "integer",
                        "description": "The line after which the text goes, counting from 1; 0 puts it before the first line.",
                    },
                    "new_str": {"type": "string", "description": "The text to insert (one or more whole lines)."},
                },
                "required": ["path", "insert_line", "new_str"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            UNDO_EDIT,
            "Undo the last change made to a file with str_replace, insert or create (a created file is removed); "
            "several calls undo several changes, newest first. Changes made with bash are not undone.",
            {
                "type": "object",
                "properties": {"path": path_arg},
                "required": ["path"],
                "additionalProperties": False,
            },
        ),
        ToolDef(
            SUBMIT,
            "Hand in your changes (the repository's diff against the starting commit) when the issue is resolved. "
            "The first call shows your diff and asks you to review it; calling submit again ends the task.",
            {"type": "object", "properties": {}, "additionalProperties": False},
        ),
    )


@dataclass
class ToolOutcome:
    """What a tool call produced: the observation and the ``tool_calls`` row's fields."""

    observation: str
    exit_code: int | None = None
    duration_s: float = 0.0
    output_bytes: int = 0
    timed_out: bool = False
    error: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def info(self) -> dict[str, Any]:
        """``Step.info``: exit_code, duration_s, output_bytes, timed_out, error (and extras)."""
        return {
            "exit_code": self.exit_code,
            "duration_s": self.duration_s,
            "output_bytes": self.output_bytes,
            "timed_out": self.timed_out,
            "error": self.error,
            **self.extra,
        }


def refused(message: str) -> ToolOutcome:
    """A call the tool refused: the observation says why, ``error`` holds the same line."""
    return ToolOutcome(observation=f"Error: {message}", error=message)


_JSON_TYPES = {"string": str, "integer": int, "array": list, "object": dict}


def check_args(tool: ToolDef, args: Mapping[str, Any] | None) -> str | None:
    """Why ``args`` do not fit ``tool``'s schema (a missing, unknown or wrongly typed argument), or None."""
    if not isinstance(args, Mapping):
        return f"{tool.name}: the arguments must be a JSON object"
    props: Mapping[str, Any] = tool.parameters.get("properties", {})
    for name in tool.parameters.get("required", ()):
        if name not in args:
            return f"{tool.name}: missing argument {name!r}"
    for name, value in args.items():
        if name not in props:
            accepted = ", ".join(props) or "none"
            return f"{tool.name}: unknown argument {name!r} (accepted: {accepted})"
        schema = props[name]
        kind = schema["type"]
        if isinstance(value, str) and not _encodable(value):
            return f"{tool.name}: argument {name!r} is not valid Unicode (it holds a lone surrogate)"
        if isinstance(value, bool) or not isinstance(value, _JSON_TYPES[kind]):
            return f"{tool.name}: argument {name!r} must be a{'n' if kind[0] in 'aeio' else ''} {kind}, got {_json_type(value)}"
        if isinstance(value, list):
            item = schema.get("items", {}).get("type")
            if item and any(isinstance(v, bool) or not isinstance(v, _JSON_TYPES[item]) for v in value):
                return f"{tool.name}: argument {name!r} must be a list of {item}s"
            lo, hi = schema.get("minItems"), schema.get("maxItems")
            if (lo is not None and len(value) < lo) or (hi is not None and len(value) > hi):
                return f"{tool.name}: argument {name!r} must have {lo} items, got {len(value)}"
    return None


def _encodable(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _json_type(value: Any) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    for name, cls in _JSON_TYPES.items():
        if isinstance(value, cls):
            return name
    return "number" if isinstance(value, float) else type(value).__name__


def repo_relative(workdir: str, path: str) -> str | None:
    """``path`` (absolute, or relative to ``workdir``) as a path relative to the repository root
    (``.`` for the root itself), or None when it leads outside the repository."""
    root = posixpath.normpath(workdir)
    full = posixpath.normpath(path if posixpath.isabs(path) else posixpath.join(root, path))
    if full == root:
        return "."
    if not full.startswith(root.rstrip("/") + "/"):
        return None
    rel = full[len(root.rstrip("/")) + 1 :]
    return rel


def bad_path(tool: str, path: str) -> ToolOutcome | None:
    """The refusal of a path no file can have (a NUL byte, longer than :data:`PATH_MAX_BYTES`), or None."""
    if "\x00" in path:
        return refused(f"{tool}: the path {_short(path)!r} contains a NUL byte")
    size = len(path.encode("utf-8", errors="surrogatepass"))
    if size > PATH_MAX_BYTES:
        return refused(f"{tool}: the path is {size} bytes long, over the {PATH_MAX_BYTES}-byte limit ({_short(path)!r})")
    return None


def _short(path: str, keep: int = 120) -> str:
    """``path`` for a message: at most ``keep`` characters, the cut said."""
    return path if len(path) <= keep else path[:keep] + "..."


def file_refusal(tool: str, shown: str, workdir: str, exc: Exception, *, writing: bool = False) -> ToolOutcome:
    """The refusal for a file operation the model's path or file made fail (``exc``), naming the path."""
    if isinstance(exc, OutsideRepository):
        return refused(f"{tool}: {shown} leads outside the repository {workdir} (through a symbolic link)")
    if isinstance(exc, FileTooLarge):
        return refused(f"{tool}: {shown} is {exc.size} bytes, too large for the editor (at most {exc.limit} bytes); use bash")
    if isinstance(exc, FileNotFoundError):
        return refused(f"{tool}: {shown} does not exist")
    if isinstance(exc, IsADirectoryError):
        return refused(f"{tool}: {shown} is a directory")
    if isinstance(exc, NotADirectoryError):
        return refused(f"{tool}: {shown}: a folder on the way is a file")
    if isinstance(exc, PermissionError):
        return refused(f"{tool}: {shown} cannot be {'written' if writing else 'read'} (permission denied)")
    if isinstance(exc, OSError) and exc.errno == errno.ELOOP:
        return refused(f"{tool}: {shown}: too many levels of symbolic links")
    if isinstance(exc, OSError) and exc.errno == errno.EINVAL:
        return refused(f"{tool}: {shown} is not a regular file (a fifo, a device or a socket)")
    if isinstance(exc, OSError):
        return refused(f"{tool}: {shown} cannot be {'written' if writing else 'read'}: {exc.strerror or exc}")
    return refused(f"{tool}: {shown}: {exc}")


#: what a file operation raises for the model's path or file (a broken sandbox is a SandboxError,
#: never one of these)
FILE_ERRORS = (OSError, ValueError)


def shown_path(workdir: str, rel: str) -> str:
    """The absolute path the model sees for a repository-relative ``rel``."""
    root = posixpath.normpath(workdir)
    return root if rel == "." else posixpath.join(root, rel)


def cap_text(text: str, limit: int) -> tuple[str, bool]:
    """``text`` cut to ``limit`` UTF-8 bytes (on a character boundary) and whether it was cut."""
    data = text.encode("utf-8")
    if len(data) <= limit:
        return text, False
    return data[:limit].decode("utf-8", errors="ignore"), True


def numbered(lines: list[str], first: int) -> str:
    """``lines`` numbered from ``first`` as ``cat -n`` prints them (six-wide number, a tab)."""
    return "\n".join(f"{n:6}\t{line}" for n, line in enumerate(lines, start=first))


def command_observation(res: CommandResult, limits: SandboxLimits, timeout_s: float) -> str:
    """What the model sees of a command: its output, then a bracketed line for a cut, a timeout or
    a non-zero exit; ``[no output]`` when there is nothing else."""
    parts = [res.output.rstrip("\n")] if res.output.strip() else []
    if res.truncated:
        parts.append(f"[output cut: the first {limits.output_bytes} of {res.output_bytes} bytes are shown]")
    if res.timed_out:
        parts.append(f"[the command was stopped after {timeout_s:g} seconds]")
    elif res.exit_code not in (0, None):
        parts.append(f"[exit code {res.exit_code}]")
    return "\n".join(parts) if parts else "[no output]"


def run_bash(sandbox: Sandbox, limits: SandboxLimits, command: str, session: ShellSession | None = None) -> ToolOutcome:
    """One shell command, its observation and the ``tool_calls`` fields: in the episode's
    ``session`` (the ``bash`` tool: cd and variables carry over) or afresh in the repository
    folder (a text action, as mini-SWE-agent runs each command in its own subprocess)."""
    if not command.strip():
        return refused("bash: the command is empty")
    if "\x00" in command:
        return refused("bash: the command contains a NUL byte")
    size = len(command.encode("utf-8", errors="surrogatepass"))
    if size > COMMAND_MAX_BYTES:
        return refused(
            f"bash: the command is {size} bytes, over the {COMMAND_MAX_BYTES}-byte limit; "
            "write a long script to a file with create, then run it"
        )
    if session is None:
        res = sandbox.run(command, timeout_s=limits.command_timeout_s)
        observation = command_observation(res, limits, limits.command_timeout_s)
    else:
        ran = session.run(command, timeout_s=limits.command_timeout_s)
        res = ran.result
        observation = command_observation(res, limits, limits.command_timeout_s)
        if ran.restored:
            observation += "\n[the shell session goes on from its state before this command]"
    return ToolOutcome(
        observation=observation,
        exit_code=res.exit_code,
        duration_s=res.duration_s,
        output_bytes=res.output_bytes,
        timed_out=res.timed_out,
    )


def _read_text(sandbox: Sandbox, rel: str, shown: str, *, tool: str) -> str | ToolOutcome:
    """A file's text (at most :data:`EDIT_MAX_BYTES`), or ``tool``'s refusal saying why it cannot
    be had (outside the repository, missing, a folder, too large, not UTF-8...)."""
    try:
        data = sandbox.read_file(rel, max_bytes=EDIT_MAX_BYTES)
    except FILE_ERRORS as exc:
        return file_refusal(tool, shown, sandbox.workdir, exc)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return refused(f"{tool}: {shown} is not a UTF-8 text file")


def _write(sandbox: Sandbox, rel: str, shown: str, data: bytes, *, tool: str) -> ToolOutcome | None:
    """Write ``data``; None when written, else ``tool``'s refusal naming the path."""
    try:
        sandbox.write_file(rel, data)
    except FILE_ERRORS as exc:
        return file_refusal(tool, shown, sandbox.workdir, exc, writing=True)
    return None


def _finish(out: ToolOutcome, limits: SandboxLimits, started: float, *, more: bool = False) -> ToolOutcome:
    """``out`` with its output cut to the cap (and the cut said), timed, sized. ``more``: the
    observation is itself a cut of a longer text (a view of a file read only up to the cap), whose
    whole size is not known: the cut is said without it."""
    size = len(out.observation.encode("utf-8"))
    text, cut = cap_text(out.observation, limits.output_bytes)
    if more:
        text += f"\n[output cut: the first {limits.output_bytes} bytes are shown; view a smaller view_range to see the rest]"
    elif cut:
        text += f"\n[output cut: the first {limits.output_bytes} of {size} bytes are shown]"
    out.observation = text
    out.output_bytes = size
    out.duration_s = time.monotonic() - started
    return out


def run_view(sandbox: Sandbox, limits: SandboxLimits, path: str, view_range: list[int] | None) -> ToolOutcome:
    """A file numbered (``view_range`` lines only) or a folder's listing two levels deep. The
    sandbox reads the lines asked, at most the output cap of them (numbering only lengthens them,
    so the observation is never short of the cap): the rest of the file never reaches the worker."""
    started = time.monotonic()
    if (bad := bad_path("view", path)) is not None:
        return bad
    rel = repo_relative(sandbox.workdir, path)
    if rel is None:
        return refused(f"view: {path} is outside the repository {sandbox.workdir}")
    shown = shown_path(sandbox.workdir, rel)
    first, last = (1, None) if view_range is None else (view_range[0], None if view_range[1] == -1 else view_range[1])
    try:
        part = sandbox.read_lines(rel, max(first, 1), None if last is None or last < first else last, limits.output_bytes)
    except IsADirectoryError:
        if view_range is not None:
            return refused(f"view: view_range is for files, and {shown} is a directory")
        res = sandbox.run(f"find {shlex.quote(shown)} -maxdepth 2 -not -path '*/.*' | LC_ALL=C sort")
        if res.exit_code != 0:
            return refused(f"view: cannot list {shown}: {res.output.strip()}")
        head = f"Files and directories in {shown}, up to 2 levels deep (hidden ones left out):\n"
        return _finish(ToolOutcome(observation=head + res.output.rstrip("\n"), exit_code=0), limits, started)
    except FILE_ERRORS as exc:
        return file_refusal("view", shown, sandbox.workdir, exc)
    n = part.total_lines
    if view_range is not None:
        if not 1 <= first <= max(n, 1):
            return refused(f"view: view_range starts at line {first}, but {shown} has {n} lines")
        if last is None:
            last = n
        elif not first <= last <= n:
            return refused(f"view: view_range ends at line {last}; it must be -1 or between {first} and {n}")
    text = _utf8(part.data, cut=part.truncated)
    if text is None:
        return refused(f"view: {shown} is not a UTF-8 text file")
    body = numbered(_lines(text), first)
    head = f"{shown} (lines {first}-{last} of {n}):\n" if view_range is not None else f"{shown}:\n"
    return _finish(ToolOutcome(observation=head + body, exit_code=0), limits, started, more=part.truncated)


def _utf8(data: bytes, *, cut: bool) -> str | None:
    """``data`` decoded, or None when it is not UTF-8; a character ``cut`` in two at the end (the
    sandbox cut the lines at a byte count) is left out."""
    for drop in range(4 if cut else 1):
        try:
            return data[: len(data) - drop].decode("utf-8")
        except UnicodeDecodeError:
            continue
    return None


def _snippet(text: str, start_line: int, n_lines: int) -> str:
    """The lines ``start_line`` (1-based) .. +``n_lines`` with :data:`SNIPPET_LINES` around, numbered."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    lo = max(start_line - SNIPPET_LINES, 1)
    hi = min(start_line + max(n_lines, 1) - 1 + SNIPPET_LINES, len(lines))
    return numbered(lines[lo - 1 : hi], lo)


class EditHistory:
    """What each file held before each of the editor's changes in this episode, for ``undo_edit``
    (the release's editor keeps a per-file history: tools/edit_anthropic/bin/str_replace_editor
    :354-360, 632-639). None: the file did not exist (a ``create``), so undoing removes it."""

    def __init__(self) -> None:
        self._before: dict[str, list[str | None]] = {}

    def record(self, rel: str, before: str | None) -> None:
        self._before.setdefault(rel, []).append(before)

    def pop(self, rel: str) -> tuple[bool, str | None]:
        """(whether there was a change to undo, the text before it)."""
        stack = self._before.get(rel)
        if not stack:
            return False, None
        return True, stack.pop()


def run_str_replace(
    sandbox: Sandbox, limits: SandboxLimits, path: str, old_str: str, new_str: str, history: EditHistory | None = None
) -> ToolOutcome:
    """Replace the one occurrence of ``old_str``; refused when it occurs zero or several times."""
    started = time.monotonic()
    if (bad := bad_path("str_replace", path)) is not None:
        return bad
    rel = repo_relative(sandbox.workdir, path)
    if rel is None:
        return refused(f"str_replace: {path} is outside the repository {sandbox.workdir}")
    shown = shown_path(sandbox.workdir, rel)
    if not old_str:
        return refused("str_replace: old_str is empty")
    text = _read_text(sandbox, rel, shown, tool="str_replace")
    if isinstance(text, ToolOutcome):
        return text
    count = text.count(old_str)
    if count == 0:
        return refused(f"str_replace: old_str does not occur in {shown} (it must match exactly, whitespace included)")
    first_at = text.find(old_str)
    second_at = text.find(old_str, first_at + 1)
    if second_at != -1:
        starts, at = [], first_at
        while at != -1:
            starts.append(text.count("\n", 0, at) + 1)
            at = text.find(old_str, at + 1)
        where = ", ".join(str(n) for n in starts)
        return refused(
            f"str_replace: old_str occurs {len(starts)} times in {shown} (starting on lines {where}); "
            "include more surrounding lines so it occurs once"
        )
    new_text = text[:first_at] + new_str + text[first_at + len(old_str) :]
    if (failed := _write(sandbox, rel, shown, new_text.encode("utf-8"), tool="str_replace")) is not None:
        return failed
    if history is not None:
        history.record(rel, text)
    line = text.count("\n", 0, first_at) + 1
    snippet = _snippet(new_text, line, new_str.count("\n") + 1)
    obs = f"Edited {shown}. The region around the change now reads:\n{snippet}"
    return _finish(ToolOutcome(observation=obs, exit_code=0), limits, started)


def run_create(
    sandbox: Sandbox, limits: SandboxLimits, path: str, file_text: str, history: EditHistory | None = None
) -> ToolOutcome:
    """Write a new file; refused when the path exists."""
    started = time.monotonic()
    if (bad := bad_path("create", path)) is not None:
        return bad
    rel = repo_relative(sandbox.workdir, path)
    if rel is None or rel == ".":
        return refused(f"create: {path} is outside the repository {sandbox.workdir}")
    shown = shown_path(sandbox.workdir, rel)
    try:  # resolved in the sandbox first: a link out of the repository is refused before anything is asked of it
        sandbox.read_lines(rel, 1, 1, 0)
    except FileNotFoundError:
        pass
    except IsADirectoryError:
        return refused(f"create: {shown} already exists; use str_replace to change it")
    except FILE_ERRORS as exc:
        return file_refusal("create", shown, sandbox.workdir, exc, writing=True)
    else:
        return refused(f"create: {shown} already exists; use str_replace to change it")
    exists = sandbox.run(f"test -e {shlex.quote(shown)} || test -L {shlex.quote(shown)}")
    if exists.exit_code == 0:
        return refused(f"create: {shown} already exists; use str_replace to change it")
    if (failed := _write(sandbox, rel, shown, file_text.encode("utf-8"), tool="create")) is not None:
        return failed
    if history is not None:
        history.record(rel, None)
    n = len(file_text.split("\n")) - (1 if file_text.endswith("\n") else 0)
    return _finish(ToolOutcome(observation=f"Created {shown} ({n} lines).", exit_code=0), limits, started)


def _lines(text: str) -> list[str]:
    """``text``'s lines as ``cat -n`` counts them (a final newline ends the last line, adds none)."""
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    return lines


def run_insert(
    sandbox: Sandbox, limits: SandboxLimits, path: str, insert_line: int, new_str: str, history: EditHistory | None = None
) -> ToolOutcome:
    """Put ``new_str`` after line ``insert_line`` (0: before the first line), as the release's
    editor does (tools/edit_anthropic/bin/str_replace_editor:594-630); refused for a line outside
    0..the file's line count."""
    started = time.monotonic()
    if (bad := bad_path("insert", path)) is not None:
        return bad
    rel = repo_relative(sandbox.workdir, path)
    if rel is None:
        return refused(f"insert: {path} is outside the repository {sandbox.workdir}")
    shown = shown_path(sandbox.workdir, rel)
    text = _read_text(sandbox, rel, shown, tool="insert")
    if isinstance(text, ToolOutcome):
        return text
    lines = _lines(text)
    if not 0 <= insert_line <= len(lines):
        return refused(f"insert: insert_line {insert_line} is outside {shown}, which has {len(lines)} lines (0 to {len(lines)})")
    added = _lines(new_str) or [""]
    ends = text.endswith("\n") or not text
    new_text = "\n".join(lines[:insert_line] + added + lines[insert_line:]) + ("\n" if ends else "")
    if (failed := _write(sandbox, rel, shown, new_text.encode("utf-8"), tool="insert")) is not None:
        return failed
    if history is not None:
        history.record(rel, text)
    snippet = _snippet(new_text, insert_line + 1, len(added))
    obs = f"Edited {shown}. The region around the inserted lines now reads:\n{snippet}"
    return _finish(ToolOutcome(observation=obs, exit_code=0), limits, started)


#: removes a file at its path resolved in the sandbox, only when that stays in the repository
#: (exit 3 otherwise); the link itself when the path ends in one
REMOVE_INSIDE = (
    'root=$(realpath -e -- {root}) && r=$(realpath -m -s -- {path}) && d=$(realpath -m -- "${{r%/*}}") '
    '&& case "$d/" in "$root"/*) rm -f -- "$d/${{r##*/}}" ;; *) exit 3 ;; esac'
)


def run_undo_edit(sandbox: Sandbox, limits: SandboxLimits, path: str, history: EditHistory) -> ToolOutcome:
    """Put the file back as it was before the editor's last change to it (remove a file the
    editor created); refused when the editor has not changed it (the release: "no edit history",
    str_replace_editor:632-639)."""
    started = time.monotonic()
    if (bad := bad_path("undo_edit", path)) is not None:
        return bad
    rel = repo_relative(sandbox.workdir, path)
    if rel is None:
        return refused(f"undo_edit: {path} is outside the repository {sandbox.workdir}")
    shown = shown_path(sandbox.workdir, rel)
    had, before = history.pop(rel)
    if not had:
        return refused(f"undo_edit: no change made with the editor to {shown} is left to undo")
    if before is None:
        # removed at the path resolved in the sandbox, and only inside the repository (a folder
        # on the way may have become a link out of it since the file was created)
        res = sandbox.run(REMOVE_INSIDE.format(root=shlex.quote(sandbox.workdir), path=shlex.quote(shown)))
        if res.exit_code == 3:
            history.record(rel, before)
            return refused(f"undo_edit: {shown} leads outside the repository {sandbox.workdir} (through a symbolic link)")
        if res.exit_code != 0:
            history.record(rel, before)
            return refused(f"undo_edit: cannot remove {shown}: {res.output.strip()}")
        return _finish(
            ToolOutcome(observation=f"Undid the creation of {shown}: the file is removed.", exit_code=0), limits, started
        )
    if (failed := _write(sandbox, rel, shown, before.encode("utf-8"), tool="undo_edit")) is not None:
        history.record(rel, before)
        return failed
    body = numbered(_lines(before), 1)
    obs = f"Undid the last change to {shown}. It now reads:\n{body}"
    return _finish(ToolOutcome(observation=obs, exit_code=0), limits, started)
