"""The numbers the ReCAP paper reports (docs/recap-reference-notes.md), shown next to ours.

Only numbers live here; a report matches them to its rows by benchmark, split, method, model and
ablation name, and leaves the reference empty where nothing matches.
"""

from __future__ import annotations

import re

#: pass@1 (%) by (benchmark, split or None for any split) and method, GPT-4o unless noted
MAIN: dict[tuple[str, str | None], dict[str, float]] = {
    ("robotouille", "synchronous"): {"recap": 70.0, "adapt": 40.0, "react": 38.0, "act": 31.0, "cot": 14.0, "standard": 12.0},
    ("robotouille", "asynchronous"): {"recap": 53.0, "react": 24.0, "adapt": 14.0, "act": 8.0, "cot": 5.0, "standard": 2.0},
    ("alfworld", None): {"recap": 91.0, "react": 84.0, "act": 74.0, "adapt": 71.6},
    ("fever", None): {"recap": 63.5, "react": 63.5, "cot": 58.5, "act": 58.5, "standard": 53.5},
}

#: Robotouille sync tasks 2, 4, 6 (64-message cap): model name fragment -> {method: %}
CROSS_MODEL: dict[str, dict[str, float]] = {
    "gpt-4o": {"react": 63.0, "recap": 90.0},
    "qwen2.5-32b": {"react": 10.0, "recap": 33.0},
    "qwen2.5-72b": {"react": 23.0, "recap": 53.0},
    "llama-4": {"react": 37.0, "recap": 60.0},
    "deepseek-v3": {"react": 57.0, "recap": 87.0},
}

#: Robotouille sync task 6, 128-message context
ABLATIONS: dict[str, float] = {
    "original": 80.0, "think_many": 70.0, "no_think": 60.0, "name_only": 55.0,
    "level_5": 70.0, "level_4": 60.0, "level_3": 10.0, "level_2": 0.0,
}

TREE = {"task": "robotouille synchronous task 6", "depth": 3.4, "branching_factor": 12.5, "episodes": 20}
COSTS = {
    "robotouille_sync_task6": {"calls_per_episode": 74.95, "calls_sd": 27.87, "usd_per_episode": 7.77, "usd_sd": 3.45},
    "alfworld_134_games_usd": {"recap": 118.40, "react": 37.89},
}


def main_reference(env_split: str, method: str) -> float | None:
    bench, _, split = env_split.partition("/")
    for key in ((bench, split), (bench, None)):
        if key in MAIN and method in MAIN[key]:
            return MAIN[key][method]
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
