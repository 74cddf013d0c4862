"""The numbers the ReCAP paper reports, and the protocol each of its tables was run under.

Only numbers and protocols live here (checked against ``ReCAP.tex`` and the reference notes);
:mod:`reports.paper_section` matches them to a run's arms and shows a paper number only beside an
arm run under the same protocol (:func:`mismatch` says why not, in one short phrase).

Why a protocol per table: the paper's tables come from different runs - the main and per-task
tables from the full benchmarks, the cross-model table from synchronous tasks 2, 4, 6 with a
64-message window, the ablations (and, we take it, the task-tree analysis and the task-6 cost,
"20 runs" of task 6) with a 128-message window. Windows count messages: the paper's K = 64
rounds is 128 messages. The step caps follow the authors' released configs per method and task
(:data:`RELEASED_MULTIPLIERS`).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

#: display names of the methods (the paper's spelling)
METHOD_NAMES = {"recap": "ReCAP", "adapt": "ADaPT", "react": "ReAct", "cot": "CoT", "act": "Act", "standard": "Standard"}
#: column order of the main table (Table 1) and of the per-task tables (appendix)
MAIN_ORDER = ("recap", "adapt", "react", "cot", "act", "standard")
TASK_ORDER = ("recap", "react", "adapt", "act", "cot", "standard")

#: pass@1 (%) by (benchmark, split or None for any split) and method, GPT-4o unless noted
MAIN: dict[tuple[str, str | None], dict[str, float]] = {
    ("robotouille", "synchronous"): {"recap": 70.0, "adapt": 40.0, "react": 38.0, "act": 31.0, "cot": 14.0, "standard": 12.0},
    ("robotouille", "asynchronous"): {"recap": 53.0, "react": 24.0, "adapt": 14.0, "act": 8.0, "cot": 5.0, "standard": 2.0},
    ("alfworld", None): {"recap": 91.0, "react": 84.0, "act": 74.0, "adapt": 71.6},
    ("fever", None): {"recap": 63.5, "react": 63.5, "cot": 58.5, "act": 58.5, "standard": 53.5},
    # GPT-4.1 (2025-04-14), temperature 0, no demonstrations, the 500 instances (Table 1's last row,
    # appendix "SWE-bench Verified Experiment Details"); ReAct is mini-SWE-agent's leaderboard number
    ("swe-verified", None): {"recap": 44.8, "react": 39.58},
}
#: methods that stand in another method's column of the main table: the paper's ReAct baseline on
#: SWE-bench Verified is mini-SWE-agent (ReCAP.tex, Baselines: "we used mini-SWE-agent ... as the
#: ReAct baseline")
COLUMN_OF = {"mini_swe": "react"}
#: SWE-bench Verified as the paper ran it: every one of its 500 instances once, GPT-4.1, temperature 0
SWE_VERIFIED = "swe-verified"
SWE_VERIFIED_INSTANCES = 500
SWE_MODEL_NAME = "GPT-4.1 (2025-04-14)"
SWE_TEMPERATURE = 0.0
#: main-table numbers that are not the paper's own GPT-4o runs: never comparable, with the reason
FOREIGN: dict[tuple[str, str], str] = {
    ("alfworld", "adapt"): "the paper's ADaPT ALFWorld number (71.6) is GPT-3.5, quoted from the ADaPT paper",
}

#: per-task pass@1 (%), GPT-4o (appendix tables): split -> task index -> method -> %
_TASK_COLUMNS = ("recap", "react", "adapt", "act", "cot", "standard")
_SYNC_ROWS = (
    (100, 60, 70, 90, 40, 50),
    (80, 30, 70, 30, 30, 20),
    (80, 40, 50, 10, 10, 10),
    (80, 60, 50, 30, 10, 0),
    (90, 80, 80, 70, 10, 10),
    (70, 60, 60, 30, 30, 30),
    (70, 50, 20, 20, 0, 0),
    (60, 0, 0, 0, 0, 0),
    (50, 0, 0, 10, 10, 0),
    (20, 0, 0, 20, 0, 0),
)
_ASYNC_ROWS = (
    (50, 20, 20, 20, 10, 10),
    (80, 40, 40, 20, 10, 10),
    (90, 10, 10, 0, 20, 0),
    (40, 40, 20, 20, 0, 0),
    (50, 10, 0, 0, 10, 0),
    (80, 60, 50, 10, 0, 0),
    (70, 30, 0, 0, 0, 0),
    (40, 30, 0, 10, 0, 0),
    (20, 0, 0, 0, 0, 0),
    (10, 0, 0, 0, 0, 0),
)
PER_TASK: dict[str, dict[int, dict[str, float]]] = {
    split: {i: {m: float(v) for m, v in zip(_TASK_COLUMNS, row)} for i, row in enumerate(rows)}
    for split, rows in (("synchronous", _SYNC_ROWS), ("asynchronous", _ASYNC_ROWS))
}
#: the per-task tables' "Average" row (= the mean of the ten rows, and the main table's values)
PER_TASK_AVERAGE: dict[str, dict[str, float]] = {
    "synchronous": {"recap": 70.0, "react": 38.0, "adapt": 40.0, "act": 31.0, "cot": 14.0, "standard": 12.0},
    "asynchronous": {"recap": 53.0, "react": 24.0, "adapt": 14.0, "act": 8.0, "cot": 5.0, "standard": 2.0},
}

#: Robotouille sync tasks 2, 4, 6 (64-message cap): the paper's model column -> {method: %}
CROSS_MODEL: dict[str, dict[str, float]] = {
    "gpt-4o": {"react": 63.0, "recap": 90.0},
    "qwen2.5-32b": {"react": 10.0, "recap": 33.0},
    "qwen2.5-72b": {"react": 23.0, "recap": 53.0},
    "llama-4": {"react": 37.0, "recap": 60.0},
    "deepseek-v3": {"react": 57.0, "recap": 87.0},
}
CROSS_MODEL_NAMES = {
    "gpt-4o": "GPT-4o",
    "qwen2.5-32b": "Qwen2.5-32B",
    "qwen2.5-72b": "Qwen2.5-72B",
    "llama-4": "LLaMA-4 (400B)",
    "deepseek-v3": "DeepSeek-V3 (671B)",
}

#: Robotouille sync task 6, 128-message context, in the paper's column order
ABLATIONS: dict[str, float] = {
    "original": 80.0,
    "think_many": 70.0,
    "no_think": 60.0,
    "name_only": 55.0,
    "level_5": 70.0,
    "level_4": 60.0,
    "level_3": 10.0,
    "level_2": 0.0,
}

TREE = {"task": "robotouille synchronous task 6", "depth": 3.4, "branching_factor": 12.5, "episodes": 20}
COSTS = {
    "robotouille_sync_task6": {"calls_per_episode": 74.95, "calls_sd": 27.87, "usd_per_episode": 7.77, "usd_sd": 3.45},
    "alfworld_134_games_usd": {"recap": 118.40, "react": 37.89},
}
#: ALFWorld's unseen split as the paper ran it
ALFWORLD_GAMES = 134
ALFWORLD_TYPES = ("clean", "cool", "examine", "heat", "put", "puttwo")


#: the step-cap multipliers of the authors' released Robotouille configs that are not x4:
#: method -> split -> task index -> multiplier (ReCAP: robotouille-recap/conf/experiments/ReAct/
#: synchronous/last-reasoning-action-mpc_{2,4,6}.yaml:43; ReAct: robotouille-baselines/conf/experiments/
#: ReAct/synchronous/original_{2,4,6}.yaml:40, original_9.yaml:39, ReAct/asynchronous/
#: original_{2,4,6}.yaml:39; Act: Act/*/original_*.yaml:39-40, x2 everywhere; Standard:
#: IO/*/io.yaml:39, x1.5; ADaPT (Adapt/*/original_*.yaml:39) and CoT (IO-CoT/*/io-cot.yaml:39): x4
#: everywhere). examples/paper/main-robotouille.yaml runs each method at these
#: (tests/pipeline/test_step_multipliers.py checks every example unit against this table)
RELEASED_MULTIPLIERS: dict[str, dict[str, dict[int, float]]] = {
    "recap": {"synchronous": {2: 3.0, 4: 3.0, 6: 3.0}},
    "react": {"synchronous": {2: 3.0, 4: 3.0, 6: 3.0, 9: 2.0}, "asynchronous": {2: 2.0, 4: 3.0, 6: 3.0}},
    "act": {split: dict.fromkeys(range(10), 2.0) for split in ("synchronous", "asynchronous")},
    "standard": {split: dict.fromkeys(range(10), 1.5) for split in ("synchronous", "asynchronous")},
}


def step_multiplier(split: str, task_index: int | None, method: str = "recap") -> float:
    """The step-cap multiplier of the authors' released Robotouille configs for one task and method."""
    if task_index is None:
        return 4.0
    return RELEASED_MULTIPLIERS.get(method, {}).get(split, {}).get(task_index, 4.0)


def expected_window(protocol: Protocol, benchmark: str, method: str) -> int | None:
    """The window (messages) ``method`` runs with under ``protocol``; None: not checked (Act keeps
    its whole history, CoT/Standard make one call). The main tables follow the ``paper`` profile:
    ReCAP and ADaPT 128 messages (K = 64 rounds), ReAct 64 on Robotouille (the benchmark's
    original ReAct) and 128 on ALFWorld (the released react.py); tables with a stated window
    (cross-model 64, ablations 128) use it for every method."""
    if method in ("act", "cot", "standard"):
        return None
    if protocol.fixed_window or method != "react":
        return protocol.window
    return 64 if benchmark == "robotouille" else 128


#: the windows FEVER's numbers were measured with (the released code printed them): ReCAP's
#: history cut at 32 messages (fever-recap/MATRIX/MATRIX/chatbot.py:42-44; the released profile's
#: ``window: 32``, workers/envs/fever/protocol.py); the notebooks resend the whole trajectory and
#: CoT/Standard make one call, so no window is checked for them
FEVER_RELEASED_WINDOWS: dict[str, int] = {"recap": 32}


def task_index(task: str | None) -> int | None:
    """``6_lettuce_tomato_cheeseburger`` -> 6 (Robotouille tasks start with their number)."""
    m = re.match(r"^(\d+)_", task or "")
    return int(m.group(1)) if m else None


def paper_model(provider_model: str | None) -> str | None:
    """The paper's model a provider model string is (``openai/gpt-4o-2024-08-06`` -> ``gpt-4o``),
    or None. Provider prefixes, ``-instruct`` and ``-turbo`` are ignored; GPT-4o must be the
    paper's snapshot (2024-08-06) or the bare alias; ``gpt-4o-mini`` is not GPT-4o."""
    name = (provider_model or "").lower().rsplit("/", 1)[-1]
    if name in ("gpt-4o", "gpt-4o-2024-08-06"):
        return "gpt-4o"
    name = re.sub(r"-(instruct|turbo)$", "", re.sub(r"-(instruct|turbo)$", "", name))
    if name in ("qwen2.5-32b", "qwen2.5-72b", "deepseek-v3"):
        return name
    if name == "deepseek-chat":  # DeepSeek's API name of V3
        return "deepseek-v3"
    if name.startswith("llama-4-maverick"):
        return "llama-4"
    return None


@dataclass(frozen=True)
class Protocol:
    """What an arm must have run for a paper number to stand beside it."""

    table: str
    models: tuple[str, ...]  # paper model names (paper_model)
    window: int
    profile: str = "paper"
    #: "split:task_index" keys of the Robotouille tasks, or ALFWorld task types; None: every task of the split
    tasks: tuple[str, ...] | None = None
    #: True: the table states one window for every method (a setting of the sweep); False: each
    #: method's profile window (:func:`expected_window`)
    fixed_window: bool = False


#: windows in messages (one unit of ``window``): the paper's "K = 64 back-and-forth rounds" is 128
#: messages, the released main value (robotouille-recap/main.py:55); the cross-model table states
#: "a hard cap of 64 context messages", the ablations "context length 128 = messages stored"
PROTOCOLS = {
    "main": Protocol("main", ("gpt-4o",), 128),
    "per_task": Protocol("per_task", ("gpt-4o",), 128),
    "cross_model": Protocol(
        "cross_model", tuple(CROSS_MODEL), 64, tasks=("synchronous:2", "synchronous:4", "synchronous:6"), fixed_window=True
    ),
    "ablations": Protocol("ablations", ("gpt-4o",), 128, tasks=("synchronous:6",), fixed_window=True),
    "costs_alfworld": Protocol("costs_alfworld", ("gpt-4o",), 128),
    "costs_task6": Protocol("costs_task6", ("gpt-4o",), 128, tasks=("synchronous:6",)),
    "trees": Protocol("trees", ("gpt-4o",), 128, tasks=("synchronous:6",)),
}

ROBOTOUILLE_TASKS = 10
#: the paper's FEVER set: 200 claims (the release's shuffle of indices 0..7404 with seed 42)
FEVER_CLAIMS = 200
#: the sample of paper_dev.jsonl behind each method's FEVER number: main.py's shuffle with seed 42
#: (ReCAP, CoT, Standard: conf/config.toml) or the notebooks' with 233 (ReAct, Act: React.ipynb /
#: baseline_act.ipynb cell 4); the report compares an arm with the paper only over that sample
FEVER_SAMPLE_SEED = {"recap": 42, "cot": 42, "standard": 42, "react": 233, "act": 233}
#: what the release's own output says against the paper's FEVER numbers
FEVER_NOTE = (
    "FEVER: ReCAP, CoT and Standard are compared over main.py's seed-42 sample, ReAct and Act over the notebooks' "
    "seed-233 sample (sample_seed). The paper's Act 58.5 is not what the release's notebook printed: "
    "fever-recap/baseline_act.ipynb cell 4 ends at 108/200 = 54.0 (its ReAct, React.ipynb, at 127/200 = 63.5, the paper's number)."
)
#: FEVER's labels, the per-label breakdown's rows (the environment reports a claim's label as its task)
FEVER_LABELS = ("SUPPORTS", "REFUTES", "NOT ENOUGH INFO")


@dataclass(frozen=True)
class ArmProtocol:
    """What an arm ran in one cell's scope (read from its episode rows)."""

    provider_model: str | None
    test_double: bool
    profile: str | None
    windows: tuple[int | None, ...]
    benchmark: str
    split: str
    #: (task, step multipliers seen on it)
    tasks: tuple[tuple[str, tuple[float, ...]], ...]
    method: str = "recap"
    #: episodes the cell counts (FEVER's number needs the paper's 200 claims)
    episodes: int | None = None
    #: distinct instances the cell counts (SWE-bench Verified's number needs the paper's 500)
    instances: int | None = None
    #: the temperatures the arm's settings carried (None: not read; SWE-bench Verified needs 0)
    temperatures: tuple[float | None, ...] | None = None


def _task_key(split: str, task: str) -> str:
    i = task_index(task)
    return f"{split}:{i}" if i is not None else task


def mismatch(protocol: Protocol, arm: ArmProtocol, expected_tasks: Iterable[str] | None = None) -> str | None:
    """None when ``arm`` ran ``protocol``; else the first difference, as a footnote phrase.

    ``expected_tasks``: the task keys the cell covers (``synchronous:6``, ``heat``); default: the
    protocol's own tasks, or every task of the split (10 per Robotouille split, 6 ALFWorld types).
    """
    if arm.test_double:
        return "a test double, not a language model"
    if arm.benchmark == SWE_VERIFIED:
        return swe_mismatch(arm)
    model = paper_model(arm.provider_model)
    if model not in protocol.models:
        wanted = " or ".join(CROSS_MODEL_NAMES[m] for m in protocol.models)
        return f"model {arm.provider_model or '?'}, the paper used {wanted}"
    # FEVER's numbers were measured by the released code itself (the notebooks print them), so
    # the released profile is the paper's protocol there as much as the paper profile
    fever_released = arm.benchmark == "fever" and arm.profile == "released"
    if arm.profile != protocol.profile and not fever_released:
        return f"profile {arm.profile or 'none'}, the paper's runs are profile {protocol.profile}"
    windows = sorted({w for w in arm.windows if w is not None})
    want_w = FEVER_RELEASED_WINDOWS.get(arm.method) if fever_released else expected_window(protocol, arm.benchmark, arm.method)
    if want_w is not None and windows != [want_w]:
        return f"window {', '.join(map(str, windows)) or '?'} messages, the paper used {want_w}"
    if arm.benchmark == "fever" and arm.episodes is not None and arm.episodes != FEVER_CLAIMS:
        return f"{arm.episodes} claims, the paper ran {FEVER_CLAIMS}"
    got = {_task_key(arm.split, t) for t, _ in arm.tasks}
    if expected_tasks is not None:
        want = set(expected_tasks)
    elif protocol.tasks is not None:
        want = set(protocol.tasks)
    elif arm.benchmark == "robotouille":
        want = {f"{arm.split}:{i}" for i in range(ROBOTOUILLE_TASKS)}
    elif arm.benchmark == "alfworld":
        want = set(ALFWORLD_TYPES)
    else:
        want = got
    if got != want:
        missing = sorted(want - got, key=_natural)
        extra = sorted(got - want, key=_natural)
        parts = ([f"{len(got & want)} of the paper's {len(want)} tasks (missing {', '.join(missing)})"] if missing else []) + (
            [f"tasks the paper's number leaves out ({', '.join(extra)})"] if extra else []
        )
        return "ran " + "; ".join(parts)
    if arm.benchmark == "robotouille":
        for task, mults in arm.tasks:
            want_m = step_multiplier(arm.split, task_index(task), arm.method)
            if sorted(set(mults)) != [want_m]:
                got_m = ", ".join(f"x{m:g}" for m in sorted(set(mults)))
                return f"step cap {got_m} on {_task_key(arm.split, task)}, the released configs use x{want_m:g}"
    return None


def is_swe_model(provider_model: str | None) -> bool:
    """Whether a provider model string is the paper's SWE-bench model, GPT-4.1: its snapshot
    (2025-04-14) or the bare alias, any provider prefix (``gpt-4.1-mini`` is not GPT-4.1)."""
    return (provider_model or "").lower().rsplit("/", 1)[-1] in ("gpt-4.1", "gpt-4.1-2025-04-14")


def swe_mismatch(arm: ArmProtocol) -> str | None:
    """None when ``arm`` ran SWE-bench Verified as the paper did (GPT-4.1, profile paper,
    temperature 0, each of the 500 instances once); else the first difference, as a footnote phrase.
    The paper states no context window for SWE-bench (mini-SWE-agent keeps its whole history), so
    none is checked."""
    if arm.test_double:
        return "a test double, not a language model"
    if not is_swe_model(arm.provider_model):
        return f"model {arm.provider_model or '?'}, the paper used {SWE_MODEL_NAME}"
    if arm.profile != "paper":
        return f"profile {arm.profile or 'none'}, the paper's runs are profile paper"
    temps = sorted({"none" if t is None else f"{t:g}" for t in (arm.temperatures or (None,))})
    if temps != [f"{SWE_TEMPERATURE:g}"]:
        return f"temperature {', '.join(temps)}, the paper used {SWE_TEMPERATURE:g}"
    if arm.instances is not None and arm.instances != SWE_VERIFIED_INSTANCES:
        return f"ran {arm.instances} of the paper's {SWE_VERIFIED_INSTANCES} instances (a subset)"
    if arm.episodes is not None and arm.instances is not None and arm.episodes != arm.instances:
        return f"{arm.episodes} episodes over {arm.instances} instances, the paper ran each instance once (pass@1)"
    return None


def _natural(key: str) -> tuple[str, int]:
    head, _, tail = key.partition(":")
    return (head, int(tail)) if tail.isdigit() else (key, -1)


# -- lookups kept for the general success section ----------------------------------------------------


def main_reference(env_split: str, method: str) -> float | None:
    """The paper's main-table success rate (%) for ``method`` on ``env_split`` ("robotouille/synchronous",
    "alfworld", ...); None when the paper has none."""
    bench, _, split = env_split.partition("/")
    column = COLUMN_OF.get(method, method) if bench == SWE_VERIFIED else method
    for key in ((bench, split), (bench, None)):
        if key in MAIN and column in MAIN[key]:
            return MAIN[key][column]
    return None


def cross_model_reference(model: str, method: str) -> float | None:
    """The paper's number for ``model`` (provider prefix, ``-instruct`` and a date suffix are
    ignored, so ``openai/gpt-4o-2024-08-06`` matches but ``gpt-4o-mini`` does not)."""
    name = model.lower().rsplit("/", 1)[-1]
    name = re.sub(r"-\d{4}-\d{2}-\d{2}$", "", name)
    name = re.sub(r"-instruct$", "", name)
    for fragment, by_method in CROSS_MODEL.items():
        if name == fragment or (fragment == "llama-4" and name.startswith("llama-4-maverick")):
            return by_method.get(method)
    return None
