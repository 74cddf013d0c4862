"""Version wording, banner/goal parsing, the walkthrough expert and the rule texts."""

from __future__ import annotations

import pytest

from workers.envs.alfworld.expert import WalkthroughExpert
from workers.envs.alfworld.rules import failure_hints_text, rules_text
from workers.envs.alfworld.wording import extract_goal, strip_banner, to_version


def test_put_and_move_convert_both_ways():
    assert to_version("move tomato 1 to toaster 1", "2.1.1") == "put tomato 1 in/on toaster 1"
    assert to_version("put tomato 1 in/on toaster 1", "2.1.2") == "move tomato 1 to toaster 1"
    assert to_version("move tomato 1 to toaster 1", "2.1.2") == "move tomato 1 to toaster 1"
    assert to_version("put tomato 1 in/on toaster 1", "2.1.1") == "put tomato 1 in/on toaster 1"
    for same in (
        "go to toaster 1",
        "take potato 1 from countertop 2",
        "heat mug 3 with microwave 1",
        "look",
        "move",
        "put it down",
    ):
        assert to_version(same, "2.1.1") == same
        assert to_version(same, "2.1.2") == same
    with pytest.raises(ValueError, match="^unknown ALFWorld game-file version '3'; use one of: 2.1.1, 2.1.2$"):
        to_version("look", "3")


def test_banner_and_goal():
    text = (
        "-= Welcome to TextWorld, ALFRED! =-\n\nYou are in the middle of a room. Looking quickly "
        "around you, you see a desk 1.\n\nYour task is to: put a hot mug in cabinet."
    )
    body = strip_banner(text)
    assert body == (
        "You are in the middle of a room. Looking quickly around you, you see a desk 1."
        "\n\nYour task is to: put a hot mug in cabinet."
    )
    assert extract_goal(body) == "put a hot mug in cabinet"
    assert extract_goal("no task here") is None
    assert strip_banner("You arrive at loc 3.") == "You arrive at loc 3."


def test_expert_advances_only_on_the_next_walkthrough_action():
    expert = WalkthroughExpert(["go to desk 1", "take pen 1 from desk 1", "move pen 1 to shelf 2"], "2.1.1")
    assert expert.remaining() == ["go to desk 1", "take pen 1 from desk 1", "put pen 1 in/on shelf 2"]
    expert.observe("look")
    expert.observe("take pen 1 from desk 1")  # not the next one
    assert expert.remaining()[0] == "go to desk 1"
    expert.observe("go to desk 1")
    assert expert.remaining() == ["take pen 1 from desk 1", "put pen 1 in/on shelf 2"]
    expert.observe("take pen 1 from desk 1")
    expert.observe("put pen 1 in/on shelf 2")
    assert expert.remaining() == []
    expert.observe("look")
    assert expert.remaining() == []
    expert.reset()
    assert len(expert.remaining()) == 3
    assert WalkthroughExpert(["move pen 1 to shelf 2"], "2.1.2").remaining() == ["move pen 1 to shelf 2"]


def test_rules_carry_the_paper_rule_and_the_version_wording():
    r11, r12 = rules_text("2.1.1", 50), rules_text("2.1.2", 50)
    for r in (r11, r12):
        assert "You can hold only one object at a time." in r
        assert 'check with "inventory"' in r
        assert "uses one of your 50 steps" in r
        assert "  go to <receptacle> | open <receptacle> | close <receptacle>\n" in r
    assert "  take <object> from <receptacle> | put <object> in/on <receptacle>\n" in r11
    assert "  take <object> from <receptacle> | move <object> to <receptacle>\n" in r12
    assert "uses one of your 30 steps" in rules_text("2.1.1", 30)
    hints = failure_hints_text()
    assert hints.startswith("- Copy the command word for word from the valid actions, numbers included.\n")
    assert "must be opened before" in hints
    assert "Go to a receptacle before" in hints
