"""FEVER's released baselines under ``prompts: release``: what the authors' four notebooks send, read at run time.

The release runs ReAct, Act, CoT and Standard on FEVER from Jupyter notebooks in ``fever-recap/``
(GitHub ``ReCAP-Stanford/ReCAP`` at 2fb112f), not from a prompt file alone:

* ``React.ipynb`` / ``baseline_act.ipynb``, cell 4: the demonstration is the value of
  ``prompt_dict['webthink_simple3']`` (ReAct) / ``['webact_simple3']`` (Act) of the JSON file the
  cell names (``folder + prompt_file``: ``./prompts/fever.json``), sent as the first user message;
  the loop ``for i in range(1, 11)`` asks once per round and on the last round (``if i == 10``)
  puts a sentence of the cell's own before the turn label;
* ``baseline_cot.ipynb`` / ``baseline_standard.ipynb``, cell 2: ``run_hotpotqa`` builds one user
  message from a string literal (``prompt = ...``) and an f-string appended to it
  (``prompt += f"...{question}..."``).

Each notebook is read as JSON, the cell's source parsed with :mod:`ast` (never executed) and the
literals taken from the syntax tree, so no sentence of theirs is stored here. What this module
gives :mod:`workers.release.texts`: the files a method reads (:func:`sources`), the text a unit's
digest covers (:func:`read_part`) and the messages in the released structure (:func:`release_prompt`).
"""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path

from recap.release_prompt import ReleasePrompt

FEVER_DIR = "fever-recap"
#: method -> (notebook, index of the cell holding the method's loop)
NOTEBOOKS = {
    "react": ("React.ipynb", 4),
    "act": ("baseline_act.ipynb", 4),
    "cot": ("baseline_cot.ipynb", 2),
    "standard": ("baseline_standard.ipynb", 2),
}
#: the functions of the loop cells that hold the loop (React.ipynb cell 4 ``webthink``; the
#: I/O notebooks' cell 2 ``run_hotpotqa``)
LOOP_FUNCTION = {"react": "webthink", "act": "webthink", "cot": "run_hotpotqa", "standard": "run_hotpotqa"}
#: the Part picks this module reads
NOTEBOOK_PICK = "notebook"
PROMPT_FILE_PICK = "notebook-prompt-file"


class NotebookError(ValueError):
    """A notebook cell does not hold the code this module reads (an edited release)."""


@dataclass(frozen=True)
class ReActLoop:
    """What the ReAct/Act loop cell fixes: the JSON file and key of the demonstration, how many
    rounds it asks (``range(1, N + 1)``), which round is the last and the sentence put before
    that round's label."""

    prompt_file: str
    prompt_key: str
    rounds: int
    final_round: int
    final_sentence: str


@dataclass(frozen=True)
class OneCall:
    """What the CoT/Standard cell sends: ``before`` + the reset's question + ``after``."""

    before: str
    after: str


def covers(method: str) -> bool:
    """Whether this module builds ``method``'s FEVER release (ReCAP's is elsewhere)."""
    return method in NOTEBOOKS


def notebook_path(method: str) -> str:
    """The release path of ``method``'s notebook."""
    return f"{FEVER_DIR}/{NOTEBOOKS[method][0]}"


def cell_source(notebook_text: str, cell: int) -> str:
    """The source of code cell ``cell`` of a notebook's JSON (NotebookError otherwise)."""
    try:
        cells = json.loads(notebook_text)["cells"]
        found = cells[cell]
    except (ValueError, KeyError, IndexError, TypeError) as exc:
        raise NotebookError(f"not a notebook with a cell {cell} ({type(exc).__name__}: {exc})") from None
    if not isinstance(found, dict) or found.get("cell_type") != "code":
        raise NotebookError(f"cell {cell} is not a code cell")
    source = found.get("source")
    return "".join(source) if isinstance(source, list) else str(source)


def _function(tree: ast.Module, name: str) -> ast.FunctionDef:
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            return node
    raise NotebookError(f"no function {name}() in the cell")


def _constant_assign(nodes: list[ast.stmt], name: str) -> str:
    """The string literal last assigned to ``name`` at this level."""
    found: str | None = None
    for node in nodes:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            value = node.value
            if isinstance(value, ast.Constant) and isinstance(value.value, str):
                found = value.value
    if found is None:
        raise NotebookError(f"no string literal assigned to {name}")
    return found


def _subscript_key(nodes: list[ast.stmt], name: str) -> str:
    """The literal key of ``name = <dict>['<key>']``."""
    for node in nodes:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == name for t in node.targets):
            value = node.value
            if isinstance(value, ast.Subscript) and isinstance(value.slice, ast.Constant) and isinstance(value.slice.value, str):
                return value.slice.value
    raise NotebookError(f"no {name} = prompt_dict['...'] in the cell")


def react_loop(source: str) -> ReActLoop:
    """Read the ReAct/Act loop cell (React.ipynb / baseline_act.ipynb cell 4): ``folder`` +
    ``prompt_file`` and the ``webthink_prompt`` key at the top; in ``webthink``, the
    ``for i in range(1, N)`` loop and its ``if i == K: prompt = '<sentence>' + prompt``."""
    tree = ast.parse(source)
    prompt_file = _constant_assign(tree.body, "folder") + _constant_assign(tree.body, "prompt_file")
    key = _subscript_key(tree.body, "webthink_prompt")
    loop = next((n for n in _function(tree, "webthink").body if isinstance(n, ast.For)), None)
    if loop is None or not isinstance(loop.iter, ast.Call) or len(loop.iter.args) != 2:
        raise NotebookError("webthink() has no for i in range(1, N) loop")
    start, stop = (ast.literal_eval(a) for a in loop.iter.args)
    final: tuple[int, str] | None = None
    for node in loop.body:
        if not isinstance(node, ast.If) or not isinstance(node.test, ast.Compare) or not node.body:
            continue
        bound = node.test.comparators[0]
        assign = node.body[0]
        if (
            isinstance(bound, ast.Constant)
            and isinstance(bound.value, int)
            and bound.value != start
            and isinstance(assign, ast.Assign)
            and isinstance(assign.value, ast.BinOp)
            and isinstance(assign.value.left, ast.Constant)
            and isinstance(assign.value.left.value, str)
        ):
            final = (bound.value, assign.value.left.value)
    if final is None:
        raise NotebookError("webthink() has no final-round sentence (if i == N: prompt = '...' + prompt)")
    return ReActLoop(prompt_file.removeprefix("./"), key, int(stop) - int(start), final[0], final[1])


def _fstring_text(node: ast.expr, name: str) -> tuple[str, str]:
    """(before, after) the one ``{name}`` placeholder of an f-string (or all of a literal, '')."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value, ""
    if not isinstance(node, ast.JoinedStr):
        raise NotebookError("the prompt is not a string literal")
    before, after, seen = "", "", False
    for part in node.values:
        if isinstance(part, ast.Constant):
            if seen:
                after += str(part.value)
            else:
                before += str(part.value)
        elif isinstance(part, ast.FormattedValue) and isinstance(part.value, ast.Name) and part.value.id == name and not seen:
            seen = True
        else:
            raise NotebookError(f"the prompt has a placeholder other than one {{{name}}}")
    return before, after


def one_call(source: str) -> OneCall:
    """Read the CoT/Standard cell (baseline_cot.ipynb / baseline_standard.ipynb cell 2): in
    ``run_hotpotqa``, ``prompt = <literal>`` then ``prompt += f"...{question}..."``."""
    fn = _function(ast.parse(source), "run_hotpotqa")
    base: str | None = None
    frame: tuple[str, str] | None = None
    for node in fn.body:
        if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "prompt" for t in node.targets):
            text, rest = _fstring_text(node.value, "question")
            if rest:
                raise NotebookError("the first prompt literal has a placeholder")
            base = text
        elif isinstance(node, ast.AugAssign) and isinstance(node.target, ast.Name) and node.target.id == "prompt":
            frame = _fstring_text(node.value, "question")
    if base is None or frame is None:
        raise NotebookError("run_hotpotqa() does not build prompt = '...' then prompt += f'...{question}...'")
    return OneCall(base + frame[0], frame[1])


def demonstration_path(loop: ReActLoop) -> str:
    """The release path of the demonstration file the loop cell names (relative to ``fever-recap``)."""
    return f"{FEVER_DIR}/{loop.prompt_file}"


def _read(folder: Path, rel: str) -> str:
    return (folder / rel).read_text(encoding="utf-8-sig")


def read_loop(folder: Path, method: str) -> ReActLoop:
    """The ReAct/Act loop cell of ``method``'s notebook in ``folder``, read."""
    return react_loop(cell_source(_read(folder, notebook_path(method)), NOTEBOOKS[method][1]))


def read_one_call(folder: Path, method: str) -> OneCall:
    """The CoT/Standard cell of ``method``'s notebook in ``folder``, read."""
    return one_call(cell_source(_read(folder, notebook_path(method)), NOTEBOOKS[method][1]))


def demonstration(folder: Path, loop: ReActLoop) -> str:
    """The ReAct/Act demonstration: the value under the cell's key in the file it names."""
    try:
        value = json.loads(_read(folder, demonstration_path(loop)))[loop.prompt_key]
    except KeyError:
        raise NotebookError(f"{loop.prompt_file} has no key {loop.prompt_key!r}") from None
    if not isinstance(value, str):
        raise NotebookError(f"{loop.prompt_file}[{loop.prompt_key!r}] is not text")
    return value


def release_text(folder: Path, method: str) -> tuple[tuple[str, ...], str]:
    """(the files read, the text a unit's digest covers): ReAct/Act the demonstration, the
    final-round sentence and the round count; CoT/Standard the text around the question."""
    if method in ("react", "act"):
        loop = read_loop(folder, method)
        text = "\n\n".join((demonstration(folder, loop), loop.final_sentence, f"rounds {loop.rounds}, final {loop.final_round}"))
        return (notebook_path(method), demonstration_path(loop)), text
    call = read_one_call(folder, method)
    return (notebook_path(method),), f"{call.before}\n\n{call.after}"


def release_prompt(folder: Path, method: str) -> ReleasePrompt:
    """The released structure (``first_turn: notebook``, :mod:`recap.baselines.notebook_loop`):
    ReAct/Act pin the demonstration as the first user message (React.ipynb cell 4:
    ``history.append({"role": "user", "content": webthink_prompt})``) and carry the rounds and the
    final-round sentence; CoT/Standard pin nothing and carry the text around the question."""
    if method in ("react", "act"):
        loop = read_loop(folder, method)
        return ReleasePrompt(
            (("user", demonstration(folder, loop)),),
            first_turn="notebook",
            rounds=loop.rounds,
            final_round=loop.final_round,
            final_sentence=loop.final_sentence,
        )
    call = read_one_call(folder, method)
    return ReleasePrompt((), first_turn="notebook", claim_frame=(call.before, call.after))
