"""What an episode row records is what ran (issue 36 item 4): each method's recorded window
(``method_config.window``) is the one its calls were held to, ``null`` where none was applied.

A real offline sweep (the offline expert test double through the driver, in-process) plays one
Robotouille instance under ``profile: paper`` with every method Robotouille runs, each asked for a
4-message window. Act under ``paper`` keeps its whole history there (the released Act,
workers/envs/robotouille/protocol.py), so the setting is not applied: its row must say ``null``,
not 4; every other method's calls hold at most 4 messages past the pins, and the episodes are
long enough (25 steps) for the window to bind."""

from __future__ import annotations

import json

import pytest

from pipeline.driver import Driver, prepare
from pipeline.gateway_backend import make_backend
from pipeline.spec import parse_spec
from pipeline.sqlview import open_tables
from pipeline.store import RunStore

METHODS = ("recap", "react", "act", "cot", "standard", "adapt")


def _sweep(out) -> str:
    methods = "".join(f"  - {{method: {m}, label: {m}, profile: paper, settings: {{window: 4}}}}\n" for m in METHODS)
    return (
        f"run: windows\noutput: {out}\nmodels:\n  - model: offline/expert\nmethods:\n{methods}"
        "environments:\n  - benchmark: robotouille\n    tasks: [synchronous/2]\n    limit: 1\nworkers: 2\n"
    )


@pytest.mark.slow
def test_each_methods_recorded_window_is_the_one_its_longest_call_was_held_to(tmp_path):
    out = tmp_path / "run"
    text = _sweep(out)
    spec = parse_spec(text, "sweep.yaml")
    Driver(prepare(spec, text), make_backend(spec), progress="off", executor="in-process").run()
    con = open_tables(RunStore(str(out)))[0]
    recorded = {label: json.loads(cfg) for label, cfg in con.execute("SELECT label, method_config FROM episodes").fetchall()}
    pinned = {(e, s) for e, s in con.execute("SELECT episode_id, seq FROM messages WHERE pinned").fetchall()}
    longest: dict[str, int] = {}
    total: dict[str, int] = {}
    rows = con.execute("SELECT e.label, c.episode_id, c.window_seqs FROM llm_calls c JOIN episodes e USING (episode_id)")
    for label, episode_id, seqs in rows.fetchall():
        past_pins = sum((episode_id, s) not in pinned for s in seqs)
        longest[label] = max(longest.get(label, 0), past_pins)
        total[label] = max(total.get(label, 0), len(seqs))
    assert sorted(recorded) == sorted(longest) == sorted(METHODS)
    assert {m: recorded[m]["window"] for m in METHODS} == {
        "recap": 4,
        "react": 4,
        "act": None,  # the whole history: the sweep's 4 is not applied
        "cot": 4,
        "standard": 4,
        "adapt": 4,
    }
    for m in METHODS:
        window = recorded[m]["window"]
        bound = total[m] if recorded[m]["window_counts_pins"] else longest[m]
        if window is None:
            assert longest[m] > 4, m  # the calls did carry more than the setting
        else:
            assert bound <= window, (m, bound, window)
    # the window binds for the methods that ask more than once (one plan call: CoT, Standard)
    assert {m: longest[m] for m in METHODS if m not in ("cot", "standard")} == {"recap": 4, "react": 4, "act": 48, "adapt": 4}
    con.close()


@pytest.mark.parametrize(
    "method, benchmark, profile, window",
    [
        ("act", "robotouille", "paper", None),  # the released Act: no window (its 64-message trim is commented out)
        ("act", "alfworld", "paper", None),
        ("act", "blocksworld", "paper", 128),
        ("react", "robotouille", "paper", 64),
        ("recap", "swe", "released", None),  # swebench-recap: the whole history
        ("recap", "swe", "paper", 128),
        ("cot", "robotouille", "paper", 128),
        ("adapt", "alfworld", "paper", 128),
    ],
)
def test_the_recorded_window_is_the_applied_one_and_the_unit_hash_keeps_the_setting(method, benchmark, profile, window):
    from pipeline.units import recorded_config
    from workers.episode_worker import build_agent

    config = build_agent(method, profile=profile, benchmark=benchmark).config
    assert json.loads(config.recorded_json())["window"] == config.applied_window() == window
    # everything else as resolved; the hashed settings (to_json) are untouched
    assert {k: v for k, v in json.loads(config.recorded_json()).items() if k != "window"} == {
        k: v for k, v in json.loads(config.to_json()).items() if k != "window"
    }
    assert recorded_config(method, config.to_json()) == config.recorded_json()


def test_react_with_only_the_last_exchange_records_that_window():
    from workers.episode_worker import build_agent

    config = build_agent("react", profile="paper", benchmark="blocksworld", settings={"history": "last"}).config
    assert (config.window, json.loads(config.recorded_json())["window"]) == (128, 2)
