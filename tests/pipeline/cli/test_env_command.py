"""``recap env``: playing by hand (any letter case, step counts, the goal once) and listing into
a pipe that closes early."""

from __future__ import annotations

import io
import sys
from pathlib import Path

from pipeline.cli import main
from pipeline.cli.env import match_action
from recap.blocksworld import BENCHMARK

REPO = Path(__file__).resolve().parents[3]
ROBOTOUILLE = REPO.parent / "shared" / "data" / "robotouille"


def test_match_action_by_number_case_and_spacing():
    valid = ("Move robot1 from stove1 to table1", "Do nothing")
    assert match_action("2", valid) == "Do nothing"
    assert match_action("move ROBOT1  from stove1 to Table1", valid) == "Move robot1 from stove1 to table1"
    assert match_action("3", valid) == "3" and match_action("fly", valid) == "fly"


def test_play_shows_step_counts_and_accepts_any_case(capsys, monkeypatch):
    env = BENCHMARK.make("blocksworld/3@1")
    start = env.reset()
    plan = env.expert_plan()
    lines = [plan[0].upper()] + plan[1:]
    monkeypatch.setattr(sys, "stdin", io.StringIO("\n".join(lines) + "\n"))
    assert main(["env", "play", "blocksworld/3@1"]) == 0
    out = capsys.readouterr().out
    assert out.count(f"Goal: {start.goal}") == 1
    steps = [line for line in out.splitlines() if line.startswith("Step ")]
    assert steps == [f"Step {i} of {env.max_steps}" for i in range(len(plan) + 1)]
    assert out.rstrip().endswith(f"Episode over after {len(plan)} steps: SUCCESS")


def test_play_robotouille_prints_the_goal_once(capsys, monkeypatch):
    monkeypatch.setenv("ROBOTOUILLE_DATA", str(ROBOTOUILLE))
    monkeypatch.setattr(sys, "stdin", io.StringIO("q\n"))
    assert main(["env", "play", "robotouille/synchronous/0_cheese_sandwich@42"]) == 0
    out = capsys.readouterr().out
    assert out.count("Goal: ") == 1 and "Step 0 of 40" in out


class _ClosedPipe(io.StringIO):
    """A reader that went away after the first line (``recap env list ... | head -1``)."""

    def write(self, text: str) -> int:
        if self.getvalue():
            raise BrokenPipeError(32, "Broken pipe")
        return super().write(text)


def test_list_into_a_closed_pipe_ends_quietly(capsys):
    from pipeline.cli.env import list_main

    out = _ClosedPipe()
    assert list_main("blocksworld", None, out) == 0
    assert out.getvalue() == "blocksworld/3@1"
    assert capsys.readouterr().err == ""  # no count line, no traceback after the reader left


def test_show_prints_what_each_observation_changed():
    from reports.observations import observation_change

    before = "Station table1:\ntable1 has bread1\n\nPlayer robot1:\nrobot1 is at stove1\nrobot1 is holding nothing"
    after = "Station table1:\ntable1 has bread1\n\nPlayer robot1:\nrobot1 is at table1\nrobot1 is holding nothing"
    assert observation_change(before, after) == "robot1 is at table1"
    assert observation_change(after, after) == "(no change)"
    assert (
        observation_change(None, "You arrive at loc 5.\nOn the desk 1, you see a pen 2.")
        == "You arrive at loc 5. | On the desk 1, you see a pen 2."
    )
    assert observation_change("You arrive at loc 5.", "Nothing happens.") == "Nothing happens."
    assert observation_change("", "x" * 200).endswith("...") and len(observation_change("", "x" * 200)) == 120


def test_progress_after_a_stop_shows_no_eta_and_marks_nominal_spend():
    from pipeline.backend import RateStats
    from pipeline.progress import Snapshot, status_line

    running = Snapshot(
        total=10,
        done=4,
        success=2,
        running=2,
        spend_usd=1.25,
        run_cap_usd=2.0,
        eta_s=90.0,
        rates={"offline/expert (test double)": RateStats()},
    )
    line = status_line(running)
    assert "| ETA " in line and "stopped" not in line
    assert "spend $1.2500 / cap $2.00 (nominal: test doubles)" in line
    stopped = Snapshot(
        total=10,
        done=4,
        success=2,
        running=0,
        spend_usd=2.0,
        run_cap_usd=2.0,
        eta_s=90.0,
        rates={"gpt-4o": RateStats()},
        stopped="run cap $2.00 reached",
    )
    line = status_line(stopped)
    assert "ETA -- (stopped)" in line and "nominal" not in line
    # one spend figure (the live one); the stop reason names the cap, not a second, stale spend
    assert line == (
        "units 4/10 | success 2/4 | running 0 | spend $2.0000 / cap $2.00 | ETA -- (stopped) | "
        "gpt-4o: rpm -- tpm -- | run cap $2.00 reached"
    )
