"""ReCAP's released FEVER prompts (``prompts: release``), read at run time from the release folder.

The released FEVER ReCAP (``fever-recap/main.py`` -> ``hotpotqa/hotpotqa_simulator.py`` ->
``MATRIX/MATRIX/session/SessionManager.py`` -> ``MATRIX/MATRIX/chatbot.py``) builds every prompt it
sends from four files, and this module reads exactly those, so the messages equal what that code
builds and none of its text lives in this repository:

* ``MATRIX/MATRIX/prompts.py``: ``get_few_shot`` names the demonstration file it opens
  (prompts.py:2-5, ``prompts/fever_matrix.json``), whose message list is the example;
* ``MATRIX/MATRIX/chatbot.py``: the ``Prompt`` class's f-strings (the first prompt :172-186, the
  descend prompt :189-195, the four return prompts :199-256 and 282-305, the fail prompt
  :258-280) with the text each shows for an empty subtask list (:207-210, 288-291), and in
  ``chatbot()`` the demonstration's frame (:324-329, around ``str(few_shot_list)``), the
  reminder (:352-360), the final-answer prompt (:471) and the two messages after a reply it
  cannot use (:464 not JSON, :466 another error);
* ``conf/config.toml``: the rules and the (empty) system text ``main.py:44-45`` hands on;
* ``hotpotqa/hotpotqa_simulator.py``: the initial observation the runner gives before any step
  (:26, ``obs_str``).

Python files are parsed with :mod:`ast`, never run: an f-string becomes a :meth:`str.format`
template whose fields are the names it interpolates (:data:`recap.release_prompt.TEMPLATE_NAMES`).
A file that does not hold what is expected raises ReleaseMissing naming the file.
"""

from __future__ import annotations

import ast
import json
import tomllib
from pathlib import Path
from typing import Any

from recap.release_prompt import ReleasePrompt
from workers.release.folder import FETCH_COMMAND

ROOT = "fever-recap"
PROMPTS_PY = f"{ROOT}/MATRIX/MATRIX/prompts.py"
CHATBOT_PY = f"{ROOT}/MATRIX/MATRIX/chatbot.py"
CONFIG_TOML = f"{ROOT}/conf/config.toml"
SIMULATOR_PY = f"{ROOT}/hotpotqa/hotpotqa_simulator.py"
#: the demonstration file get_few_shot opens (prompts.py:3; :func:`release_prompt` checks it still does)
DEMO_JSON = f"{ROOT}/prompts/fever_matrix.json"
#: every file the released FEVER ReCAP's prompts come from (what a unit's digest covers)
SOURCES = (DEMO_JSON, PROMPTS_PY, CHATBOT_PY, CONFIG_TOML, SIMULATOR_PY)
#: chatbot.py's ``Prompt`` methods -> our template names (chatbot.py:172-305)
METHODS = {
    "generate_init_prompt": "task",
    "generate_down_prompt": "descend",
    "generate_leaf_up_prompt": "leaf_done",
    "generate_leaf_judge_done_prompt": "leaf_judge",
    "generate_leaf_up_fail_prompt": "leaf_fail",
    "generate_nonleaf_up_prompt": "nonleaf_done",
    "generate_nonleaf_judge_done_prompt": "nonleaf_judge",
}
#: chatbot()'s own f-strings, by the variable they are assigned to (:324-329, :353-360)
ASSIGNED = {"few_shot_str": "demo", "rule_str": "reminder"}


class FeverMatrixError(ValueError):
    """A released file does not hold what the released FEVER ReCAP reads from it."""


def _text(folder: Path, path: str) -> str:
    try:
        return (folder / path).read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise FeverMatrixError(f"{path} is missing in {folder}; run `{FETCH_COMMAND}`") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise FeverMatrixError(f"cannot read {path}: {exc}") from None


def demonstration_file(prompts_source: str) -> str:
    """The file ``get_few_shot`` opens (prompts.py:3), relative to ``fever-recap/`` (the released
    code runs from there, main.py)."""
    for node in ast.walk(ast.parse(prompts_source)):
        if isinstance(node, ast.FunctionDef) and node.name == "get_few_shot":
            for call in ast.walk(node):
                if isinstance(call, ast.Call) and isinstance(call.func, ast.Name) and call.func.id == "open":
                    arg = call.args[0] if call.args else None
                    if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
                        return arg.value
    raise FeverMatrixError(f"{PROMPTS_PY}: get_few_shot() opens no named file")


def template(node: ast.expr) -> str:
    """An f-string (or plain string) as a :meth:`str.format` template: literal text with its
    braces doubled, each interpolated name as ``{name}``; FeverMatrixError for anything else."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value.replace("{", "{{").replace("}", "}}")
    if not isinstance(node, ast.JoinedStr):
        raise FeverMatrixError(f"{CHATBOT_PY}: expected an f-string at line {node.lineno}")
    out = []
    for part in node.values:
        if isinstance(part, ast.Constant) and isinstance(part.value, str):
            out.append(part.value.replace("{", "{{").replace("}", "}}"))
        elif isinstance(part, ast.FormattedValue) and isinstance(part.value, ast.Name) and part.format_spec is None:
            out.append("{" + part.value.id + "}")
        else:
            raise FeverMatrixError(f"{CHATBOT_PY}: an f-string at line {node.lineno} interpolates more than a name")
    return "".join(out)


def _returned(fn: ast.FunctionDef) -> ast.expr:
    for stmt in ast.walk(fn):
        if isinstance(stmt, ast.Return) and stmt.value is not None:
            return stmt.value
    raise FeverMatrixError(f"{CHATBOT_PY}: {fn.name}() returns nothing")


def _empty_list_text(fn: ast.FunctionDef) -> str:
    """What the method shows for an empty remaining list: the string it assigns to
    ``remaining_subtask_str`` in that case (:207-210), else ``'\\n'.join([])``, nothing (:265)."""
    found = _string_assigned(fn, "remaining_subtask_str")
    return found if found is not None else ""


def _string_assigned(tree: ast.AST, name: str) -> str | None:
    """The first string literal assigned to the variable ``name`` anywhere in ``tree``, or None."""
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Assign)
            and any(isinstance(t, ast.Name) and t.id == name for t in node.targets)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        ):
            return node.value.value
    return None


def chatbot_templates(source: str) -> tuple[dict[str, str], dict[str, str]]:
    """(templates, empty-list texts) read from chatbot.py's source (see the module docstring)."""
    tree = ast.parse(source)
    templates: dict[str, str] = {}
    empty: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == "Prompt":
            for fn in node.body:
                if isinstance(fn, ast.FunctionDef) and fn.name in METHODS:
                    templates[METHODS[fn.name]] = template(_returned(fn))
                    empty[METHODS[fn.name]] = _empty_list_text(fn)
        if isinstance(node, ast.FunctionDef) and node.name == "chatbot":
            for stmt in ast.walk(node):
                if isinstance(stmt, ast.Assign) and isinstance(stmt.value, ast.JoinedStr):
                    for target in stmt.targets:
                        if isinstance(target, ast.Name) and target.id in ASSIGNED:
                            templates[ASSIGNED[target.id]] = template(stmt.value)
                if (  # llm.invoke("...") with a literal: the final-answer prompt (:471)
                    isinstance(stmt, ast.Call)
                    and isinstance(stmt.func, ast.Attribute)
                    and stmt.func.attr == "invoke"
                    and stmt.args
                    and isinstance(stmt.args[0], ast.Constant)
                ):
                    templates["final_answer"] = template(stmt.args[0])
                content = _appended_content(stmt)
                if content is not None:  # the messages after a reply it cannot use (:464, 466)
                    templates.setdefault("json_error" if isinstance(content, ast.Constant) else "error", template(content))
    missing = sorted({*METHODS.values(), *ASSIGNED.values(), "final_answer", "json_error", "error"} - set(templates))
    if missing:
        raise FeverMatrixError(f"{CHATBOT_PY}: no template for {', '.join(missing)}")
    return templates, empty


def _appended_content(node: ast.AST) -> ast.expr | None:
    """The ``content`` of a ``{"role": ..., "content": ...}`` literal a call ``x.append(...)``
    adds (chatbot.py:464, 466: the history gets a user message), else None."""
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "append" and node.args):
        return None
    arg = node.args[0]
    if not isinstance(arg, ast.Dict):
        return None
    for key, value in zip(arg.keys, arg.values, strict=True):
        if isinstance(key, ast.Constant) and key.value == "content" and isinstance(value, ast.Constant | ast.JoinedStr):
            return value
    return None


def first_observation(source: str) -> str:
    """The runner's observation before any step: the string ``run_hotpotqa`` first assigns to
    ``obs_str`` (hotpotqa_simulator.py:26)."""
    found = _string_assigned(ast.parse(source), "obs_str")
    if found is None:
        raise FeverMatrixError(f"{SIMULATOR_PY}: no initial obs_str")
    return found


def config_texts(source: str) -> tuple[str, str]:
    """(system text, rules): ``system_description`` and ``rule_description`` of config.toml, as
    main.py:44-45 hands them to the runner."""
    try:
        data = tomllib.loads(source)
    except tomllib.TOMLDecodeError as exc:
        raise FeverMatrixError(f"{CONFIG_TOML}: {exc}") from None
    system, rules = data.get("system_description", ""), data.get("rule_description")
    if not isinstance(system, str) or not isinstance(rules, str):
        raise FeverMatrixError(f"{CONFIG_TOML}: rule_description and system_description must be text")
    return system, rules


def demonstration(messages: Any) -> str:
    """``str(few_shot_list)``, the Python text of the example list (chatbot.py:324)."""
    if not isinstance(messages, list) or not all(isinstance(m, dict) for m in messages):
        raise FeverMatrixError("the FEVER demonstration file does not hold a list of messages")
    return str(messages)


def release_prompt(folder: Path) -> ReleasePrompt:
    """The released FEVER ReCAP's prompts from ``folder``: the framed demonstration as the one
    pinned user message (``ChatGPTWithMemory``'s ``fixed_prompt``, chatbot.py:330, 76), the
    templates the agent renders every later prompt with, the rules, the (empty) system text and
    the initial observation. FeverMatrixError, one line naming the file, on a file that is off."""
    demo_path = f"{ROOT}/{demonstration_file(_text(folder, PROMPTS_PY))}"
    if demo_path != DEMO_JSON:
        raise FeverMatrixError(f"{PROMPTS_PY}: get_few_shot() opens {demo_path}, not {DEMO_JSON}")
    try:
        examples = json.loads(_text(folder, demo_path))
    except ValueError as exc:
        raise FeverMatrixError(f"{demo_path} is not JSON: {exc}") from None
    templates, empty = chatbot_templates(_text(folder, CHATBOT_PY))
    system, rules = config_texts(_text(folder, CONFIG_TOML))
    demo = templates["demo"].format(few_shot_str=demonstration(examples))
    return ReleasePrompt(
        (("user", demo),),
        system=system,
        rules=rules,
        first_turn="templated",
        templates=tuple(sorted(templates.items())),
        empty_list=tuple(sorted(empty.items())),
        first_observation=first_observation(_text(folder, SIMULATOR_PY)),
    )
