"""What a method shows under ``prompts: release``: the authors' own text, read from their files.

:func:`release_text` is the text a unit's digest covers (and what a method outside
:data:`STRUCTURED` would pin as its first message, in place of our rendered demonstration; today
every method the release has prompts for is structured, :func:`release_prompt`). The text is read
from the fetched release folder (:mod:`.folder`) at run time, never stored here, and each file
yields exactly the part the released code sends before the episode's first observation:

* Python prompt files (``MATRIX/MATRIX/prompts.py``): the list of example messages a
  ``get_few_shot*`` function returns, read with :mod:`ast` (a literal, never executed), joined
  one ``role: content`` line per message as ``chatbot.py`` joins them
  (``robotouille-recap/MATRIX/MATRIX/chatbot.py:401``, ``alfworld-recap/MATRIX/MATRIX/chatbot.py:390``);
* JSON demonstration files (ALFWorld): the value under the task's key (a message list joined the
  same way, or a ReAct/Act transcript string as is);
* YAML prompt templates (Robotouille baselines, ``agents/prompt_builder/prompts``): their
  ``system`` and ``instructions`` fields;
* in-context example files (``agents/in_context_examples/data/<split>/<kind>/*.txt``): each file whole.
* FEVER's notebooks (ReAct, Act, CoT, Standard: ``fever-recap/*.ipynb``): read by
  :mod:`workers.release.fever_notebooks` (the loop cell's literals with :mod:`ast`, and the
  demonstration in the JSON file the cell names).

Parts are joined by one blank line. What each method reads (and the released file that makes it
so) is :func:`sources`. The released code's framing sentences around a demonstration live in
its Python code, not in these files: where :func:`release_prompt` needs them (ReCAP's demo header
and end line, :func:`recap_demo`) they are rebuilt in our own words in the released layout.

:func:`release_prompt` builds, from the same files, the messages in the released structure (roles,
separate example pairs) for the methods it covers (:data:`STRUCTURED`); the agent then pins those
in place of our demonstration *and* our system text and rules.
"""

from __future__ import annotations

import ast
import hashlib
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from recap.baselines.text_prompts import RELEASE_ALFWORLD_RULE
from recap.env import DataNotFoundError
from recap.release_prompt import ReleasePrompt
from workers.envs import data_paths
from workers.release import fever_matrix, fever_notebooks
from workers.release.folder import FETCH_COMMAND, LOCATION, NAME

_TEMPLATES = "robotouille-baselines/agents/prompt_builder/prompts"
_EXAMPLES = "robotouille-baselines/agents/in_context_examples/data"
_RECAP_TEMPLATES = "robotouille-recap/agents/prompt_builder/prompts"
_ALFWORLD = "alfworld-recap"
#: ALFWorld task type (our short names) -> the key suffix of the released demonstration files
#: (alfworld-recap/main.py:12-18, react_alfworld/react.py:185-192): the same names
ALFWORLD_TASKS = ("put", "clean", "heat", "cool", "examine", "puttwo")


class ReleaseMissing(DataNotFoundError):
    """The release folder is not found (or a file the method needs is absent or unreadable)."""


class ReleaseUnavailable(ValueError):
    """The release has no prompts for this method on this benchmark."""


@dataclass(frozen=True)
class Part:
    """One piece of a release text: a file, and which part of it (``few_shot:get_few_shot``,
    ``key:matrix_put_0``, ``yaml:system+instructions``, ``whole``)."""

    path: str
    pick: str


@dataclass(frozen=True)
class ReleaseText:
    """The text a method pins under ``prompts: release``, the files it came from and its digest
    (what a unit's hash covers, so an edited release file makes a different unit)."""

    parts: tuple[Part, ...]
    text: str

    @property
    def digest(self) -> str:
        return hashlib.sha256(self.text.encode("utf-8")).hexdigest()

    @property
    def files(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(p.path for p in self.parts))


def release_folder(data_dir: str | None = None) -> Path:
    """The release folder by the shared search (``RECAP_RELEASE_DATA``, recap-eval's cache,
    ``../shared/data/recap-release``); ReleaseMissing, naming the fetch command, when none qualifies."""
    rungs = data_paths.search(LOCATION, data_dir)
    used = data_paths.chosen(rungs)
    if used is not None and used.path is not None:
        return used.path
    bad = data_paths.first_explicit_error(rungs)
    where = f"{bad.path} (from {bad.step}) is not a {NAME} folder; " if bad is not None else ""
    raise ReleaseMissing(f"the authors' released prompt files ({NAME}) are not found: {where}run `{FETCH_COMMAND}`")


def sources(
    method: str, benchmark: str, split: str, task: str, think: str = "latest", name_only: bool = False
) -> tuple[Part, ...]:
    """The release files (and parts) ``method`` shows on ``benchmark`` (``split``/``task`` of the
    instance; ``think``/``name_only``: ReCAP's ablation settings); ReleaseUnavailable when the
    release has none."""
    if benchmark == "robotouille":
        if split not in ("synchronous", "asynchronous"):
            raise ReleaseUnavailable(f"no released {method} prompts for Robotouille split {split!r}")
        if method == "recap":
            # robotouille-recap/MATRIX/MATRIX/session/SessionManager.py:70-97: the ablation picks the list
            fn = "get_few_shot_no_think" if think == "none" else "get_few_shot_name_only" if name_only else "get_few_shot"
            # the first prompt's system text and rules: the template's (ReAct_agent.py:58-64 hands
            # messages[0] and [1] to the SessionManager) named by the released configs
            # (robotouille-recap/conf/experiments/ReAct/synchronous/last-reasoning-action-mpc_<n>.yaml:
            # 1.3.1 last-reasoning-action-mpc; asynchronous/last-reasoning-action-mpc_<n>.yaml: its -async)
            suffix = "-async" if split == "asynchronous" else ""
            return (
                Part("robotouille-recap/MATRIX/MATRIX/prompts.py", f"few_shot:{fn}"),
                Part(f"{_RECAP_TEMPLATES}/ReAct/1.3.1-last-reasoning-action-mpc{suffix}.yml", "yaml:system+instructions"),
            )
        # robotouille-baselines/conf/experiments/<method>/<split>/original_0.yaml (IO, IO-CoT: io.yaml,
        # io-cot.yaml): the template (prompts.action_proposal_prompt) and example_dir_path
        examples = {"react": "react_examples_omitted_obs", "adapt": "react_examples_omitted_obs"}
        examples.update(standard="io_examples", cot="io-cot_examples")
        template = {
            "react": "ReAct/1.0.0-original.yml",
            "act": "Act/1.0.0-original.yml",  # the Act configs name no examples
            "standard": "IO/1.0.0-io.yml",
            "cot": "IO/1.1.0-io-cot.yml",
            "adapt": "Adapt/custom-executor.yml",
        }
        if method not in template:
            raise ReleaseUnavailable(f"the release has no {method} prompts for robotouille")
        parts: list[Part] = []
        if method == "adapt":  # the planner's own system text and examples (ADaPT_agent.py reads both)
            parts += [
                Part(f"{_TEMPLATES}/Adapt/planner_system.txt", "whole"),
                Part(f"{_TEMPLATES}/Adapt/planner_fewshot.txt", "whole"),
            ]
        parts.append(Part(f"{_TEMPLATES}/{template[method]}", "yaml:system+instructions"))
        if method in examples:
            parts.append(Part(f"{_EXAMPLES}/{split}/{examples[method]}", "every file"))
        return tuple(parts)
    if benchmark == "alfworld":
        if task not in ALFWORLD_TASKS:
            raise ReleaseUnavailable(f"no released {method} prompts for ALFWorld task {task!r}")
        if method == "recap":  # alfworld-recap/MATRIX/MATRIX/chatbot.py:388, chatbot_no_think.py:378
            name = (
                "alfworld_3prompts_no_json_all_loc_no_think.json" if think == "none" else "alfworld_3prompts_no_json_all_loc.json"
            )
            return (Part(f"{_ALFWORLD}/MATRIX/MATRIX/{name}", f"key:matrix_{task}_0"),)
        if method == "react":  # alfworld-recap/react_alfworld/react.py:125, 206
            return (Part(f"{_ALFWORLD}/react_alfworld/alfworld_3prompts_fixed.json", f"key:react_{task}_0"),)
        if method == "act":  # alfworld-recap/act_alfworld/act.py:151, 297
            return (Part(f"{_ALFWORLD}/act_alfworld/alfworld_3prompts_act.json", f"key:react_{task}_0"),)
        raise ReleaseUnavailable(f"the release has no {method} prompts for alfworld")
    if benchmark == "fever" and method == "recap":  # main.py -> chatbot.py (workers/release/fever_matrix.py)
        return tuple(Part(path, "whole") for path in fever_matrix.SOURCES)
    if benchmark == "fever" and fever_notebooks.covers(method):  # the notebooks (fever_notebooks)
        return (Part(fever_notebooks.notebook_path(method), f"{fever_notebooks.NOTEBOOK_PICK}:{method}"),)
    raise ReleaseUnavailable(f"the release has no prompts for benchmark {benchmark!r}")


def release_text(
    folder: Path, method: str, benchmark: str, split: str, task: str, think: str = "latest", name_only: bool = False
) -> ReleaseText:
    """The text ``method`` pins on ``benchmark`` under ``prompts: release``, read from ``folder``.
    ReleaseUnavailable: the release has none; ReleaseMissing: a file is absent or unreadable."""
    parts = sources(method, benchmark, split, task, think, name_only)
    return ReleaseText(parts, "\n\n".join(_read(folder, p) for p in parts))


def _read(folder: Path, part: Part) -> str:
    path = folder / part.path
    try:
        if part.pick == "every file":
            files = sorted(p for p in path.iterdir() if p.is_file())
            if not files:
                raise ReleaseMissing(f"{NAME}: {part.path} holds no example file; run `{FETCH_COMMAND}`")
            return "\n\n".join(p.read_text(encoding="utf-8") for p in files)
        text = path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise ReleaseMissing(f"{NAME}: {part.path} is missing in {folder}; run `{FETCH_COMMAND}`") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ReleaseMissing(f"{NAME}: cannot read {part.path}: {exc}") from None
    kind, _, arg = part.pick.partition(":")
    try:
        if kind == fever_notebooks.NOTEBOOK_PICK:
            return fever_notebooks.release_text(folder, arg)[1]
        if kind == "few_shot":
            return join_messages(few_shot_literal(text, arg))
        if kind == "key":
            return _demo_value(json.loads(text)[arg])
        if kind == "yaml":
            return _yaml_fields(text, arg.split("+"))
        return text
    except (KeyError, ValueError, TypeError, SyntaxError) as exc:
        raise ReleaseMissing(
            f"{NAME}: {part.path} does not hold the expected {part.pick} ({type(exc).__name__}: {exc})"
        ) from None
    except OSError as exc:  # a file the notebook names (fever-recap/prompts/fever.json)
        raise ReleaseMissing(f"{NAME}: cannot read a file {part.path} names: {exc}; run `{FETCH_COMMAND}`") from None


def few_shot_literal(source: str, function: str) -> list[dict[str, str]]:
    """The message list ``function`` returns in a Python file, read as a literal with :mod:`ast`
    (the file is parsed, never run). ValueError when the function does not return one literal list."""
    for node in ast.parse(source).body:
        if isinstance(node, ast.FunctionDef) and node.name == function:
            for stmt in node.body:
                if isinstance(stmt, ast.Return) and stmt.value is not None:
                    return _messages(ast.literal_eval(stmt.value))
            raise ValueError(f"{function}() returns no literal")
    raise ValueError(f"no function {function}()")


def _messages(value: Any) -> list[dict[str, str]]:
    if not isinstance(value, list) or not all(
        isinstance(m, dict) and isinstance(m.get("role"), str) and isinstance(m.get("content"), str) for m in value
    ):
        raise ValueError("not a list of {role, content} messages")
    return value


def join_messages(messages: Sequence[dict[str, str]]) -> str:
    """One ``role: content`` line per message, as the released ReCAP joins its example
    (robotouille-recap/MATRIX/MATRIX/chatbot.py:401)."""
    return "\n".join(f"{m['role']}: {m['content']}" for m in messages)


def _demo_value(value: Any) -> str:
    return value if isinstance(value, str) else join_messages(_messages(value))


def _yaml_fields(text: str, fields: list[str]) -> str:
    data = yaml.safe_load(text)
    if not isinstance(data, dict):
        raise ValueError("not a mapping")
    values = [data[f] for f in fields]
    if not all(isinstance(v, str) for v in values):
        raise ValueError(f"{'/'.join(fields)} must be text")
    return "\n\n".join(v.strip("\n") for v in values)


# -- the released structure (prompts: release) ------------------------------------------------------------

#: the in-context example regexes of the released ReAct/Act agents
#: (robotouille-baselines/agents/ReAct_agent.py:23-24, Act_agent.py:23-24: the same two)
_EXAMPLE_REQUEST = re.compile(r"^Observation:\s*(.+?)\nReasoning:", re.M | re.S)
_EXAMPLE_RESPONSE = re.compile(r"(^Reasoning:\s*.+?\n\nAction:.+?)(?=Observation:|$)", re.M | re.S)
#: the released I/O agents' in-context example regexes: Standard (IO_agent.py:17-18) cuts at ``Plan:``,
#: CoT (IOCoT_agent.py:17-18) at the first ``Action:``
_IO_REQUEST = re.compile(r"^Observation:\s*(.+?)Plan:", re.M | re.S)
_IO_RESPONSE = re.compile(r"(^Plan:\s*\n.+)", re.M | re.S)
_IOCOT_REQUEST = re.compile(r"^Observation:\s*(.+?)Action:", re.M | re.S)
_IOCOT_RESPONSE = re.compile(r"(^Action:\s*.+)", re.M | re.S)
#: method -> the (request, response) regexes its released agent cuts an example file with
_EXAMPLE_CUTS = {
    "react": (_EXAMPLE_REQUEST, _EXAMPLE_RESPONSE),
    "act": (_EXAMPLE_REQUEST, _EXAMPLE_RESPONSE),
    "standard": (_IO_REQUEST, _IO_RESPONSE),
    "cot": (_IOCOT_REQUEST, _IOCOT_RESPONSE),
}
#: how the released ADaPT planner cuts its few-shot file (ADaPT_agent.py:47, 53-54)
_INTERACTION = re.compile(r"(?i)\bInteraction\s*\d+\s*\n+[-]+\n+")
_PLANNER_REQUEST = re.compile(r"Observation:(.*?)Reasoning:", re.S)
_PLANNER_RESPONSE = re.compile(r"Reasoning:(.*)", re.S)
#: methods whose released messages :func:`release_prompt` builds in the released structure
STRUCTURED = {
    "robotouille": ("react", "act", "recap", "standard", "cot", "adapt"),
    "alfworld": ("react", "act", "recap"),
    "fever": ("recap",),
}
#: the released ALFWorld ReAct's one user message before the task: a sentence, then the example
#: transcript (alfworld-recap/react_alfworld/react.py:206-208); the sentence is ours
ALFWORLD_REACT_HEADER = "Complete a task by interacting with a household. One example follows.\n"
#: the released ALFWorld Act's one user message before the task: a sentence asking for JSON, then
#: the example re-read as JSON replies (alfworld-recap/act_alfworld/act.py:297-303); ours in our words
ALFWORLD_ACT_HEADER = (
    "Act in a household until a task is done, answering with a JSON object holding an 'action' field. One example follows.\n"
)


def act_example(transcript: str) -> str:
    """The released ALFWorld Act's example, as act.py re-reads Yao et al.'s transcript before
    sending it (``parse_fewshot``, alfworld-recap/act_alfworld/act.py:255-281, joined at :301): the
    text is cut into blocks, each from a line that begins ``user`` or ``assistant`` up to the next
    such line; an assistant block that is a ``think:`` line is dropped *and so is every user block
    after it* until an assistant block that acts; an acting block becomes ``{"action": ...}``
    (``json.dumps``); the remaining blocks are joined one ``role: content`` line each."""
    lines = transcript.strip().split("\n")
    blocks: list[str] = []
    for n, line in enumerate(lines):
        if n == 0 or line[:4] == "user" or line[:9] == "assistant":
            blocks.append(line)
        else:
            blocks[-1] += "\n" + line
    kept: list[dict[str, str]] = []
    after_thought = False
    for block in blocks:
        if block[:4] == "user":
            if not after_thought:
                kept.append({"role": "user", "content": block[5:].strip()})
        elif block[:9] == "assistant":
            said = block[10:].strip()
            after_thought = said.startswith("think:")
            if not after_thought:
                kept.append({"role": "assistant", "content": json.dumps({"action": said})})
    return join_messages(kept)


def alfworld_recap_demo(few_shot: str) -> str:
    """ReCAP's one fixed user message on ALFWorld: a header line, the task's example joined one
    ``role: content`` line per message, then after a blank line an end line
    (``alfworld-recap/MATRIX/MATRIX/chatbot.py:391-398``; the same in every ``chatbot_*.py``).
    The header and end sentences are ours."""
    return f"Solve a task by acting in a household. A worked example follows.\n{few_shot}\n\nEXAMPLE OVER\n"


def recap_demo(few_shot: Sequence[dict[str, str]]) -> str:
    """ReCAP's one fixed user message on Robotouille: the example joined one ``role: content``
    line per message between a header line and, after a blank line, an end line with the
    indented closing of the released literal (``robotouille-recap/MATRIX/MATRIX/chatbot.py:401-407``;
    the same in every ``chatbot_*.py``). The header and end sentences are ours."""
    return (
        f"Below is a worked example of preparing an onion and cheese sandwich:\n{join_messages(few_shot)}\n\nEXAMPLE OVER.\n    "
    )


def release_prompt(
    folder: Path, method: str, benchmark: str, split: str, task: str, think: str = "latest", name_only: bool = False
) -> ReleasePrompt | None:
    """The messages the released code sends before the first observation, with their roles, read
    from the same files as :func:`release_text` (so the unit's digest covers them); None where
    this module does not build the released structure yet (the caller pins the joined text).

    Robotouille ReAct/Act, Standard and CoT (``robotouille-baselines``; the I/O agents build theirs
    the same way, IO_agent.py:37-40, IOCoT_agent.py:39-40): the template's ``system`` as the system
    message and its ``instructions`` as a user message, then its own ``examples`` (serializer.py:53-65),
    then every in-context example file cut by the agent's regexes (:data:`_EXAMPLE_CUTS`) into user/assistant pairs
    (agent.py:54-56, in_context_examples/retrieve_example.py:27-37; all the folder's files, since
    ``random.sample(files, max(num_examples, len(files)))`` takes each once, here in name order).
    ADaPT on Robotouille: nothing in the main context; the planner's messages (:func:`_adapt_planner`)
    and each executor's (its template Adapt/custom-executor.yml and the ReAct examples, cut by
    ReAct's regexes since every executor is a released ReActAgent: ADaPT_agent.py:237-243).
    ALFWorld: one framed user message each (ReAct: the transcript as is, react.py:206-208; Act: the
    transcript re-read by :func:`act_example`, act.py:297-303; ReCAP: the example list joined,
    chatbot.py:391-398, with an empty system text and the released rule for its first prompt)."""
    if benchmark == "fever" and fever_notebooks.covers(method):  # the notebooks' loops (fever_notebooks)
        try:
            return fever_notebooks.release_prompt(folder, method)
        except (OSError, ValueError, SyntaxError) as exc:
            raise ReleaseMissing(f"{NAME}: the {method} notebook or its prompt file cannot be read ({exc})") from None
    if method not in STRUCTURED.get(benchmark, ()):
        return None
    parts = sources(method, benchmark, split, task, think, name_only)
    if method == "recap" and benchmark == "fever":  # the released templates (workers/release/fever_matrix.py)
        try:
            return fever_matrix.release_prompt(folder)
        except fever_matrix.FeverMatrixError as exc:
            raise ReleaseMissing(f"{NAME}: {exc}") from None
    if method == "recap" and benchmark == "alfworld":
        # the framed example as the fixed message (chatbot.py:391-398); the first prompt has an
        # empty system text (SessionManager.py:83-84) and the rule main.py:70 hands it
        demo = (("user", alfworld_recap_demo(_read(folder, parts[0]))),)
        return ReleasePrompt(demo, system="", rules=RELEASE_ALFWORLD_RULE, first_turn="framed")
    if method == "recap":
        return _recap_prompt(folder, parts)
    if benchmark == "alfworld" and method == "act":  # the re-read example after a sentence (act.py:297-303)
        return ReleasePrompt((("user", ALFWORLD_ACT_HEADER + act_example(_read(folder, parts[0]))),), first_turn="framed")
    if benchmark == "alfworld":  # ReAct: the framed transcript as one user message (react.py:208)
        return ReleasePrompt((("user", ALFWORLD_REACT_HEADER + _read(folder, parts[0])),), first_turn="framed")
    if method == "adapt":  # two contexts of its own: the planner's, then each executor's
        planner = _adapt_planner(folder, parts[0], parts[1])
        return ReleasePrompt((), planner=planner, executor=_template_messages(folder, parts[2:], "react"))
    return ReleasePrompt(_template_messages(folder, parts, method))


def _adapt_planner(folder: Path, system: Part, fewshot: Part) -> tuple[tuple[str, str], ...]:
    """The released ADaPT planner's messages (ADaPT_agent.py:30-61): the system file's text as the
    system message, then each interaction of the few-shot file (split at its ``Interaction <n>``
    headings) as a user message, ``Observation:`` and what follows it up to ``Reasoning:``, and an
    assistant message, what follows ``Reasoning:``; an interaction lacking either is skipped."""
    try:
        text = (folder / system.path).read_text(encoding="utf-8").strip()
        shots = (folder / fewshot.path).read_text(encoding="utf-8")
    except OSError as exc:
        raise ReleaseMissing(f"{NAME}: cannot read an ADaPT planner file: {exc}; run `{FETCH_COMMAND}`") from None
    except UnicodeDecodeError as exc:
        raise ReleaseMissing(f"{NAME}: an ADaPT planner file is not UTF-8 text ({exc})") from None
    messages: list[tuple[str, str]] = [("system", text)]
    for block in _INTERACTION.split(shots):
        asked, answered = _PLANNER_REQUEST.search(block), _PLANNER_RESPONSE.search(block)
        if asked is not None and answered is not None:
            messages += [("user", f"Observation:{asked.group(1).strip()}"), ("assistant", answered.group(1).strip())]
    return tuple(messages)


def _template_messages(folder: Path, parts: Sequence[Part], method: str) -> tuple[tuple[str, str], ...]:
    """A released Robotouille baseline's messages: its template's, then its example pairs."""
    messages: list[tuple[str, str]] = []
    for part in parts:
        path = folder / part.path
        try:
            if part.pick == "every file":
                for file in sorted(p for p in path.iterdir() if p.is_file()):
                    text = file.read_text(encoding="utf-8")
                    request, response = _EXAMPLE_CUTS[method]
                    pairs = zip(request.findall(text), response.findall(text), strict=False)
                    for asked, answered in pairs:
                        messages += [("user", asked), ("assistant", answered)]
                continue
            data = _yaml_mapping(path.read_text(encoding="utf-8-sig"))
        except OSError as exc:
            raise ReleaseMissing(f"{NAME}: cannot read {part.path}: {exc}; run `{FETCH_COMMAND}`") from None
        except ValueError as exc:
            raise ReleaseMissing(f"{NAME}: {part.path} does not hold the expected {part.pick} ({exc})") from None
        messages += [("system", data["system"].strip("\n")), ("user", data["instructions"].strip("\n"))]
        for example in data.get("examples") or []:
            key, value = next(iter(example.items()))
            if key in ("observation", "response"):
                messages.append(("user" if key == "observation" else "assistant", str(value).strip("\n")))
    return tuple(messages)


def _recap_prompt(folder: Path, parts: Sequence[Part]) -> ReleasePrompt:
    """ReCAP on Robotouille: the framed example as the one pinned user message (the released
    ``ChatGPTWithMemory`` keeps it as ``fixed_prompt``, chatbot.py:407; no system message), and the
    template's system text and rules for the agent's first prompt (chatbot.py:410-415)."""
    examples, template = parts
    try:
        few_shot = few_shot_literal((folder / examples.path).read_text(encoding="utf-8-sig"), examples.pick.partition(":")[2])
        data = _yaml_mapping((folder / template.path).read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise ReleaseMissing(f"{NAME}: cannot read a ReCAP prompt file: {exc}; run `{FETCH_COMMAND}`") from None
    except (ValueError, SyntaxError) as exc:
        raise ReleaseMissing(f"{NAME}: a ReCAP prompt file does not hold the expected text ({exc})") from None
    return ReleasePrompt(
        (("user", recap_demo(few_shot)),), system=data["system"].strip("\n"), rules=data["instructions"].strip("\n")
    )


def _yaml_mapping(text: str) -> dict[str, Any]:
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(str(exc).splitlines()[0]) from None
    if not isinstance(data, dict) or not all(isinstance(data.get(f), str) for f in ("system", "instructions")):
        raise ValueError("system and instructions must be text")
    return data
