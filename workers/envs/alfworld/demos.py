"""One-shot ALFWorld demonstrations, one per task type, written for this project.

The paper uses one training game per task type; ALFWorld's training games are not in our data,
so each demonstration is an invented household episode (see :mod:`household`) solved with
commands in 2.1.1 wording. For every task type we write the episode once, as a method-neutral
:class:`~recap.demo_script.DemoScript`; each agent class derives its replies from it:

- ``steps``: each action with the thought that leads to it (ReAct's replies; Act's are the
  actions alone);
- the plan's thought (:func:`plan_think`) walks through the same reasoning in order (CoT's one
  reply, with every action; Standard's without the think). The paper does not run CoT and
  Standard on ALFWorld - an open-loop plan cannot look inside closed receptacles - but a sweep
  may, and then they are shown the same episode as every other method;
- ``recap``: the decomposition as (think, subtasks) in ReCAP's exact call order
  (recap/recap_agent.py): a root decomposition, a "descend" reply for every child that is not
  itself a valid action, and one "refine" reply for the parent after each child returns, until
  the winning action. The trees are at least two levels deep and show both paths into an
  action: a subtask that is already an exact valid action (executed without a call) and a
  one-item descend reply.

For game-file version 2.1.2 the same episodes are recorded in 2.1.2 wording and the command
strings in the replies are rewritten (``put X in/on Y`` -> ``move X to Y``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from recap.demo_replies import DemoReplies
from recap.demo_script import DemoScript
from recap.env import Demonstration
from workers.envs.alfworld.household import Place, Scene, record
from workers.envs.alfworld.replay import Recording, ReplayEnvironment
from workers.envs.alfworld.rules import failure_hints_text, rules_text
from workers.envs.alfworld.task_types import TASK_TYPES
from workers.envs.alfworld.wording import to_version

#: the methods whose replies the scripts yield today (the paper runs ReCAP, ReAct and Act here;
#: ADaPT's executor uses the ReAct replies). Derived by the agent classes, not listed anywhere else.
STYLES = ("recap", "react", "act", "cot", "standard")


@dataclass(frozen=True)
class _Demo:
    scene: Scene
    #: (action, the ReAct thought that leads to it), in order; the last action wins
    steps: tuple[tuple[str, str], ...]
    #: ReCAP replies in call order: (think, subtasks)
    recap: tuple[tuple[str, tuple[str, ...]], ...]


def _opened(name: str, loc: int, *contents: str) -> Place:
    return Place(name, loc, contents, openable=True)


def _on(name: str, loc: int, *contents: str) -> Place:
    return Place(name, loc, contents)


_PUT = _Demo(
    scene=Scene(
        places=(
            _on("bed 1", 9, "laptop 1", "pillow 1"),
            _on("desk 1", 4, "alarmclock 1", "creditcard 1", "pen 2"),
            _opened("drawer 1", 14),
            _opened("drawer 2", 11, "keychain 1"),
            _on("dresser 1", 17, "cd 2", "cellphone 2", "mug 1"),
            _on("garbagecan 1", 2),
            _on("shelf 1", 6, "bowl 1"),
            _on("shelf 2", 7),
            _on("sidetable 1", 20, "book 1", "desklamp 1"),
        ),
        goal="put some cellphone on bed",
    ),
    steps=(
        (
            "go to desk 1",
            "I need a cellphone and then the bed. People leave phones on a desk, a dresser or a "
            "sidetable; the desk is my first guess.",
        ),
        ("go to dresser 1", "There is no cellphone on desk 1. The dresser is the next place to look."),
        (
            "take cellphone 2 from dresser 1",
            "cellphone 2 is on dresser 1 and my hands are empty, so I pick it up.",
        ),
        ("go to bed 1", "I am carrying cellphone 2. Now I walk to the bed."),
        ("put cellphone 2 in/on bed 1", "I am at bed 1 with the cellphone; setting it down ends the task."),
    ),
    recap=(
        (
            "First I need a cellphone, then I bring it to the bed. Phones usually lie on a desk, a dresser or a sidetable.",
            ("find and take a cellphone", "go to bed 1", "place the cellphone on bed 1"),
        ),
        (
            "The desk is the likeliest spot: go there and pick up a cellphone if one is there.",
            ("go to desk 1", "take a cellphone from desk 1"),
        ),
        (
            "desk 1 has no cellphone. The dresser is the next place to search.",
            ("go to dresser 1", "take a cellphone from dresser 1"),
        ),
        ("cellphone 2 is on dresser 1 and my hands are empty.", ("take cellphone 2 from dresser 1",)),
        ("I now hold cellphone 2, so finding and taking a cellphone is done.", ()),
        (
            "I carry cellphone 2. What remains is to reach the bed and set the phone down there.",
            ("go to bed 1", "place cellphone 2 on bed 1"),
        ),
        (
            "I am at bed 1 holding cellphone 2; placing it is the last step.",
            ("place cellphone 2 on bed 1",),
        ),
        (
            "Placing the phone here is a single command: the one that puts cellphone 2 on bed 1.",
            ("put cellphone 2 in/on bed 1",),
        ),
    ),
)

_CLEAN = _Demo(
    scene=Scene(
        places=(
            _opened("cabinet 1", 3, "glassbottle 1"),
            _opened("cabinet 2", 5),
            _opened("cabinet 3", 8, "saltshaker 1"),
            _on("coffeemachine 1", 10, "mug 2"),
            _on("countertop 1", 12, "bread 1", "knife 1", "spatula 2"),
            _on("countertop 2", 15, "apple 3", "plate 1", "tomato 1"),
            _on("diningtable 1", 18, "cup 1", "fork 1", "lettuce 2"),
            _opened("drawer 1", 20, "spoon 1"),
            _opened("fridge 1", 22, "egg 1", "potato 2"),
            _on("garbagecan 1", 1),
            _opened("microwave 1", 24),
            _on("sinkbasin 1", 27, "dishsponge 1"),
            _on("stoveburner 1", 30, "pan 1"),
            _on("stoveburner 2", 31),
            _on("toaster 1", 33),
        ),
        goal="clean some plate and put it in cabinet",
    ),
    steps=(
        (
            "go to countertop 1",
            "I must find a plate, wash it at the sinkbasin and store it in a cabinet. Plates are "
            "usually on a countertop or the diningtable; I start with countertop 1.",
        ),
        ("go to countertop 2", "No plate on countertop 1. I try countertop 2."),
        ("take plate 1 from countertop 2", "plate 1 is here; I take it."),
        ("go to sinkbasin 1", "With plate 1 in hand I go to the sinkbasin to wash it."),
        ("clean plate 1 with sinkbasin 1", "I am at sinkbasin 1, so I can clean plate 1 now."),
        ("go to cabinet 2", "plate 1 is clean. Any cabinet will do; I go to cabinet 2."),
        ("open cabinet 2", "cabinet 2 is closed, so I open it before putting anything inside."),
        ("put plate 1 in/on cabinet 2", "cabinet 2 is open; putting the clean plate in it finishes the task."),
    ),
    recap=(
        (
            "Three stages: get a plate, wash it at the sinkbasin, then store it in a cabinet.",
            ("find and take a plate", "clean the plate at the sinkbasin", "put the plate in a cabinet"),
        ),
        (
            "Plates are usually on a countertop or the diningtable. Start with countertop 1.",
            ("go to countertop 1", "take a plate from countertop 1"),
        ),
        (
            "countertop 1 has bread, a knife and a spatula but no plate. Try countertop 2.",
            ("go to countertop 2", "take a plate from countertop 2"),
        ),
        ("plate 1 is on countertop 2.", ("take plate 1 from countertop 2",)),
        ("I hold plate 1, so this subtask is complete.", ()),
        (
            "I have plate 1. Next I wash it at the sinkbasin, then store it in a cabinet.",
            ("clean the plate at the sinkbasin", "put the plate in a cabinet"),
        ),
        (
            "Cleaning works on the object I carry while I stand at the sinkbasin.",
            ("go to sinkbasin 1", "clean plate 1 with sinkbasin 1"),
        ),
        ("I am at sinkbasin 1 holding plate 1.", ("clean plate 1 with sinkbasin 1",)),
        ("plate 1 is clean; this subtask is done.", ()),
        ("The plate is clean. Only storing it in a cabinet is left.", ("put the plate in a cabinet",)),
        (
            "Cabinets are closed, so first I need one that is open, then I put the plate inside.",
            ("reach an open cabinet", "put plate 1 in/on cabinet 2"),
        ),
        ("Walk to cabinet 2 and open it.", ("go to cabinet 2", "open cabinet 2")),
        ("cabinet 2 is closed; open it.", ("open cabinet 2",)),
        ("cabinet 2 is open and empty, so I have reached an open cabinet.", ()),
        ("cabinet 2 is open in front of me; put plate 1 inside.", ("put plate 1 in/on cabinet 2",)),
    ),
)

_HEAT = _Demo(
    scene=Scene(
        places=(
            _opened("cabinet 1", 2),
            _opened("cabinet 2", 4, "bowl 1"),
            _on("countertop 1", 7, "bread 2", "butterknife 1", "saltshaker 2"),
            _on("countertop 2", 9, "lettuce 1", "peppershaker 1"),
            _on("diningtable 1", 12, "fork 2", "mug 3", "spoon 2"),
            _opened("drawer 1", 14, "dishsponge 2"),
            _opened("fridge 1", 16, "egg 2", "potato 1", "tomato 2"),
            _on("garbagecan 1", 18, "papertowelroll 1"),
            _opened("microwave 1", 20),
            _on("sinkbasin 1", 23),
            _on("stoveburner 1", 25, "pot 1"),
            _on("stoveburner 2", 26),
            _on("toaster 1", 28),
        ),
        goal="heat some potato and put it in diningtable",
    ),
    steps=(
        (
            "go to countertop 1",
            "I need a potato, heated in the microwave, then placed on the diningtable. Potatoes "
            "are kept on countertops or in the fridge; I look at countertop 1 first.",
        ),
        ("go to fridge 1", "No potato on countertop 1. The fridge is the other likely place."),
        ("open fridge 1", "fridge 1 is closed; I open it to see inside."),
        ("take potato 1 from fridge 1", "potato 1 is in the fridge; I take it."),
        ("go to microwave 1", "I hold potato 1. Now I go to the microwave to heat it."),
        ("heat potato 1 with microwave 1", "I am at microwave 1 with potato 1, so I heat it."),
        ("go to diningtable 1", "potato 1 is hot. I bring it to the diningtable."),
        ("put potato 1 in/on diningtable 1", "Putting the hot potato on diningtable 1 completes the task."),
    ),
    recap=(
        (
            "Get a potato, heat it in the microwave, then set it on the diningtable.",
            ("find and take a potato", "heat the potato with microwave 1", "put the potato on diningtable 1"),
        ),
        (
            "Potatoes are kept on countertops or in the fridge. Look at countertop 1 first.",
            ("go to countertop 1", "take a potato from countertop 1"),
        ),
        (
            "No potato on countertop 1. The fridge is the other likely place; it has a door I must open.",
            ("open the fridge", "take a potato from fridge 1"),
        ),
        ("Walk to fridge 1, then open it.", ("go to fridge 1", "open fridge 1")),
        ("fridge 1 is closed; open it.", ("open fridge 1",)),
        ("fridge 1 is open and I can see potato 1 inside, so this subtask is done.", ()),
        ("potato 1 is in the open fridge in front of me.", ("take potato 1 from fridge 1",)),
        ("I hold potato 1; finding and taking a potato is complete.", ()),
        (
            "I carry potato 1. Next it must be heated, then placed on the diningtable.",
            ("heat the potato with microwave 1", "put the potato on diningtable 1"),
        ),
        (
            "The microwave heats what I carry once I stand at it.",
            ("go to microwave 1", "heat potato 1 with microwave 1"),
        ),
        ("I am at microwave 1 holding potato 1.", ("heat potato 1 with microwave 1",)),
        ("potato 1 is hot; this subtask is done.", ()),
        (
            "The hot potato has to go on the diningtable: walk there and put it down.",
            ("go to diningtable 1", "put potato 1 in/on diningtable 1"),
        ),
        ("I am at diningtable 1 with the hot potato.", ("put potato 1 in/on diningtable 1",)),
    ),
)

_COOL = _Demo(
    scene=Scene(
        places=(
            _opened("cabinet 1", 3, "plate 2"),
            _opened("cabinet 2", 6),
            _on("countertop 1", 8, "cellphone 1", "knife 2", "soapbottle 1"),
            _on("countertop 2", 11),
            _on("diningtable 1", 13, "bread 1", "tomato 1", "winebottle 1"),
            _opened("drawer 1", 15),
            _opened("fridge 1", 17, "cup 2", "lettuce 1"),
            _on("garbagecan 1", 19),
            _opened("microwave 1", 21, "mug 1"),
            _on("sinkbasin 1", 24, "spatula 1"),
            _on("stoveburner 1", 26),
            _on("toaster 1", 28),
        ),
        goal="put a cool tomato in countertop",
    ),
    steps=(
        (
            "go to diningtable 1",
            "I need a tomato, chilled in the fridge, then placed on a countertop. The diningtable often has vegetables on it.",
        ),
        ("take tomato 1 from diningtable 1", "tomato 1 is on diningtable 1; I pick it up."),
        ("go to fridge 1", "I hold tomato 1. I go to the fridge to cool it."),
        (
            "cool tomato 1 with fridge 1",
            "The fridge door is closed, but cooling is offered here, so I cool tomato 1.",
        ),
        ("go to countertop 1", "tomato 1 is cool. Any countertop will do; I go to countertop 1."),
        ("put tomato 1 in/on countertop 1", "Putting the cool tomato on countertop 1 completes the task."),
    ),
    recap=(
        (
            "Fetch a tomato, chill it in the fridge, then place it on a countertop. The diningtable "
            "is a good first place to look for vegetables.",
            (
                "go to diningtable 1",
                "take a tomato from diningtable 1",
                "cool the tomato with fridge 1",
                "put the tomato on a countertop",
            ),
        ),
        (
            "tomato 1 is on diningtable 1.",
            ("take tomato 1 from diningtable 1", "cool the tomato with fridge 1", "put the tomato on a countertop"),
        ),
        (
            "I hold tomato 1. Next I chill it, then put it on a countertop.",
            ("cool the tomato with fridge 1", "put the tomato on a countertop"),
        ),
        (
            "Standing at fridge 1 is enough to cool what I carry.",
            ("go to fridge 1", "cool tomato 1 with fridge 1"),
        ),
        (
            "fridge 1 is closed, but the cooling command is available here.",
            ("cool tomato 1 with fridge 1",),
        ),
        ("tomato 1 is cool; this subtask is done.", ()),
        ("The tomato is cool. Only placing it on a countertop is left.", ("put the tomato on a countertop",)),
        (
            "countertop 1 is a fine choice: go there and put tomato 1 down.",
            ("go to countertop 1", "put tomato 1 in/on countertop 1"),
        ),
        ("I am at countertop 1 with the cool tomato.", ("put tomato 1 in/on countertop 1",)),
    ),
)

_EXAMINE = _Demo(
    scene=Scene(
        places=(
            _on("armchair 1", 5, "pillow 1"),
            _on("bed 1", 10, "book 2", "laptop 1"),
            _on("desk 1", 13, "cd 1", "pencil 1"),
            _opened("drawer 1", 15),
            _opened("drawer 2", 16, "creditcard 2"),
            _on("garbagecan 1", 1),
            _on("shelf 1", 18, "vase 1"),
            _on("sidetable 1", 21, "alarmclock 1", "desklamp 1", "keychain 2"),
        ),
        goal="look at book under the desklamp",
    ),
    steps=(
        (
            "go to desk 1",
            "I have to hold a book and switch on the desklamp. Books are found on desks, beds or "
            "shelves, and a desk may also have the lamp; I start at desk 1.",
        ),
        ("go to bed 1", "desk 1 has neither a book nor a lamp. I check the bed."),
        ("take book 2 from bed 1", "book 2 is on bed 1; I pick it up."),
        ("go to sidetable 1", "I hold book 2. Lamps often stand on a sidetable, so I go there."),
        ("use desklamp 1", "desklamp 1 is on sidetable 1; turning it on while holding the book does the task."),
    ),
    recap=(
        (
            "I must hold a book and turn on the desklamp. I do not know yet where either one is.",
            ("find and take a book", "turn on a desklamp while holding the book"),
        ),
        (
            "Books are found on desks, beds or shelves. Check desk 1 first.",
            ("go to desk 1", "take a book from desk 1"),
        ),
        ("No book on desk 1; try bed 1.", ("go to bed 1", "take a book from bed 1")),
        ("book 2 is on bed 1.", ("take book 2 from bed 1",)),
        ("I hold book 2, so this subtask is done.", ()),
        (
            "I carry book 2. desk 1 had no lamp; a sidetable often has one, so I go there next.",
            ("go to sidetable 1", "turn on a desklamp while holding the book"),
        ),
        (
            "desklamp 1 stands on sidetable 1; switching it on while I hold book 2 completes the task.",
            ("use desklamp 1",),
        ),
    ),
)

_PUTTWO = _Demo(
    scene=Scene(
        places=(
            _on("armchair 1", 4),
            _on("coffeetable 1", 7, "newspaper 1", "remotecontrol 1", "statue 1"),
            _opened("drawer 1", 9, "remotecontrol 2"),
            _opened("drawer 2", 10),
            _on("garbagecan 1", 2),
            _on("shelf 1", 12, "vase 2"),
            _on("sidetable 1", 14, "houseplant 1", "watch 1"),
            _on("sofa 1", 16, "box 1", "pillow 2"),
            _on("tvstand 1", 18, "keychain 1"),
        ),
        goal="find two remotecontrol and put them in armchair",
    ),
    steps=(
        (
            "go to coffeetable 1",
            "Two remotes must end up in the armchair, one trip each since I can carry only one "
            "item. Remotes are often on the coffeetable.",
        ),
        ("take remotecontrol 1 from coffeetable 1", "remotecontrol 1 is here; I take it."),
        ("go to armchair 1", "I carry remotecontrol 1 to the armchair."),
        ("put remotecontrol 1 in/on armchair 1", "I put the first remote in armchair 1."),
        ("inventory", "Before fetching the second remote I check that my hands are empty."),
        (
            "go to sidetable 1",
            "I carry nothing. The coffeetable had only one remote, so I search the sidetable.",
        ),
        ("go to drawer 1", "No remote on sidetable 1. Drawers often hold remotes; I try drawer 1."),
        ("open drawer 1", "drawer 1 is closed; I open it."),
        ("take remotecontrol 2 from drawer 1", "remotecontrol 2 is in drawer 1; I take it."),
        ("go to armchair 1", "I carry remotecontrol 2 back to the armchair."),
        ("put remotecontrol 2 in/on armchair 1", "Putting the second remote in armchair 1 finishes the task."),
    ),
    recap=(
        (
            "Two remotes must end up in the armchair, one trip each because I can carry only one item at a time.",
            ("bring the first remotecontrol to armchair 1", "bring the second remotecontrol to armchair 1"),
        ),
        (
            "Remotes are often left on the coffeetable.",
            (
                "go to coffeetable 1",
                "take a remotecontrol from coffeetable 1",
                "go to armchair 1",
                "put the remote in armchair 1",
            ),
        ),
        (
            "remotecontrol 1 is on coffeetable 1.",
            ("take remotecontrol 1 from coffeetable 1", "go to armchair 1", "put the remote in armchair 1"),
        ),
        (
            "I carry remotecontrol 1; take it to the armchair.",
            ("go to armchair 1", "put remotecontrol 1 in/on armchair 1"),
        ),
        ("I am at armchair 1 holding remotecontrol 1.", ("put remotecontrol 1 in/on armchair 1",)),
        ("remotecontrol 1 is in armchair 1; the first delivery is done.", ()),
        (
            "One remote is placed. Before fetching the second I make sure my hands are empty.",
            ("inventory", "bring the second remotecontrol to armchair 1"),
        ),
        (
            "My hands are empty. The coffeetable had only one remote, so the second is elsewhere.",
            ("bring the second remotecontrol to armchair 1",),
        ),
        (
            "First find and take another remote, then carry it to the armchair.",
            ("find and take another remotecontrol", "go to armchair 1", "put the remote in armchair 1"),
        ),
        (
            "sidetable 1 is a surface where a remote could be.",
            ("go to sidetable 1", "take a remotecontrol from sidetable 1"),
        ),
        (
            "No remote on sidetable 1. Drawers often hold remotes; drawer 1 must be opened first.",
            ("go to drawer 1", "open drawer 1", "take a remotecontrol from drawer 1"),
        ),
        ("drawer 1 is closed.", ("open drawer 1", "take a remotecontrol from drawer 1")),
        ("remotecontrol 2 is in drawer 1.", ("take remotecontrol 2 from drawer 1",)),
        ("I hold remotecontrol 2; I have found another remote.", ()),
        (
            "I carry remotecontrol 2; bring it to the armchair.",
            ("go to armchair 1", "put remotecontrol 2 in/on armchair 1"),
        ),
        ("I am at armchair 1 holding remotecontrol 2.", ("put remotecontrol 2 in/on armchair 1",)),
    ),
)

_DEMOS: Mapping[str, _Demo] = {
    "put": _PUT,
    "clean": _CLEAN,
    "heat": _HEAT,
    "cool": _COOL,
    "examine": _EXAMINE,
    "puttwo": _PUTTWO,
}


def recording_for(short_type: str, version: str = "2.1.1") -> Recording:
    """The recorded episode of the demonstration for ``short_type`` in ``version`` wording."""
    demo = _demo(short_type)
    return record(
        demo.scene,
        [to_version(a, version) for a, _ in demo.steps],
        name=f"demo-{short_type}",
        split=short_type,
        task=TASK_TYPES[short_type],
        version=version,
    )


def script_for(short_type: str, version: str = "2.1.1") -> DemoScript:
    """The demonstration for ``short_type`` written once, commands in ``version`` wording."""
    demo = _demo(short_type)
    return DemoScript(
        actions=tuple(to_version(a, version) for a, _ in demo.steps),
        step_thoughts=tuple(t for _, t in demo.steps),
        plan_thought=plan_think(demo),
        decomposition=tuple((think, tuple(to_version(s, version) for s in subtasks)) for think, subtasks in demo.recap),
    )


def replies_for(short_type: str, version: str = "2.1.1") -> dict[str, list[dict[str, Any]]]:
    """The model replies per method key, as the registered agent classes derive them from the
    script (commands in ``version`` wording)."""
    return {k: [dict(r) for r in v] for k, v in DemoReplies(script=script_for(short_type, version)).items()}


def plan_think(demo: _Demo) -> str:
    """CoT's single think: the episode's reasoning, step by step, written before acting."""
    steps = " ".join(f"({i}) {thought}" for i, (_, thought) in enumerate(demo.steps, 1))
    return f"I write the whole plan now, one step per action, reasoning about where things are likely to be: {steps}"


def demonstration_name(short_type: str, version: str = "2.1.1", show_valid_actions: bool = False) -> str:
    """``alfworld-<type>``, plus ``-2.1.2`` and ``-valid-actions`` for those variants.

    Agents cache a rendered demonstration by its name, so every variant that renders to a
    different text needs its own name.
    """
    name = f"alfworld-{short_type}"
    if version != "2.1.1":
        name += f"-{version}"
    if show_valid_actions:
        name += "-valid-actions"
    return name


def demonstration_for(
    short_type: str, version: str = "2.1.1", max_steps: int = 50, *, show_valid_actions: bool = False
) -> Demonstration:
    """The demonstration for ``short_type``; ``show_valid_actions`` as in the episode's game
    environment (the replay then appends the valid actions to every observation)."""
    recording = recording_for(short_type, version)
    rules, hints = rules_text(version, max_steps), failure_hints_text()

    def make_env() -> ReplayEnvironment:
        return ReplayEnvironment(
            recording, rules=rules, failure_hints=hints, max_steps=max_steps, show_valid_actions=show_valid_actions
        )

    return Demonstration(
        name=demonstration_name(short_type, version, show_valid_actions),
        make_env=make_env,
        script=script_for(short_type, version),
    )


def _demo(short_type: str) -> _Demo:
    try:
        return _DEMOS[short_type]
    except KeyError:
        raise ValueError(f"no ALFWorld demonstration for {short_type!r}; task types: {', '.join(_DEMOS)}") from None


def demo_task_types() -> Sequence[str]:
    """The short task types that have a written demonstration (one per ALFWorld task type), in the
    order they are written."""
    return tuple(_DEMOS)
