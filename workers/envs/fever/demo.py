"""FEVER's one shared demonstration: a claim of the FEVER *training* set, solved once, for every method.

The paper uses "a single shared demonstration from the training set adapted to each agent's
prompt format". Ours is training claim 156709, "Adrienne Bailon is an accountant." (REFUTES),
written for this project: a search for her page, a lookup that finds no accounting, the verdict.
The page text is our own short summary of her Wikipedia article, served as Wikipedia-shaped HTML
to a real :class:`~workers.envs.fever.env.FeverEnvironment`, so every observation of the
demonstration is produced by the same code, in the release's format, as the episodes' are.

The example is written once as a :class:`~recap.demo_script.DemoScript` (ReCAP's decomposition,
ReAct's thoughts, Act's actions); CoT and Standard give only the verdict on FEVER, so their replies
are written here by hand: a one-action plan, ``finish[REFUTES]``, with (CoT) or without
(Standard) the reasoning.
"""

from __future__ import annotations

import html
from typing import Any

import recap.methods  # noqa: F401  (registers the agents that derive this script's replies)
from recap.demo_script import DemoScript
from recap.env import Demonstration
from workers.envs.fever.claims import Claim
from workers.envs.fever.env import DEFAULT_MAX_STEPS, FeverEnvironment
from workers.envs.fever.wiki import DEFAULT_WIKIPEDIA_URL, WikiError, search_url

#: the training claim (FEVER 1.0 train.jsonl, id 156709)
CLAIM = Claim(index=-1, id=156709, claim="Adrienne Bailon is an accountant.", label="REFUTES")
ENTITY = "Adrienne Bailon"
#: our summary of her article, one paragraph (its sentences split at ". " as the release splits)
PAGE = (
    "Adrienne Eliza Bailon Houghton (born October 24, 1983) is an American singer, actress and television host. "
    "She first became known as a member of the girl groups 3LW and The Cheetah Girls. "
    "She later co-hosted the daytime talk show The Real, which won a Daytime Emmy Award. "
    "As an actress she appeared in the Cheetah Girls films and in the film Coach Carter. "
    "She married the musician Israel Houghton in 2016."
)

SCRIPT = DemoScript(
    actions=(f"search[{ENTITY}]", "lookup[accountant]", "finish[REFUTES]"),
    step_thoughts=(
        "The claim is about Adrienne Bailon's job, so I open her Wikipedia page to see what she is known for.",
        "Her page calls her a singer, actress and television host. Before deciding I check whether "
        "the page mentions accounting anywhere.",
        "No sentence of her page mentions an accountant; she is an entertainer. The evidence contradicts the claim.",
    ),
    plan_thought=(
        "Adrienne Bailon is known as a singer from 3LW and The Cheetah Girls, an actress and a "
        "talk-show host, not as an accountant, so the claim is contradicted."
    ),
    decomposition=(
        (
            "The claim names Adrienne Bailon's profession. I read her Wikipedia page, then compare what it says with the claim.",
            ("read Adrienne Bailon's Wikipedia page", "compare her profession with the claim and give the verdict"),
        ),
        ("Searching her exact name should open her page.", (f"search[{ENTITY}]",)),
        (
            "Her page opens by calling her a singer, actress and television host. To be sure, I check "
            "whether it mentions accounting at all before comparing.",
            ("look for accounting on her page", "compare her profession with the claim and give the verdict"),
        ),
        ("A lookup for the claim's own word finds any sentence about it.", ("lookup[accountant]",)),
        (
            "No sentence mentions an accountant. What is left is the verdict.",
            ("compare her profession with the claim and give the verdict",),
        ),
        (
            "She is an entertainer, not an accountant: the evidence contradicts the claim.",
            ("finish[REFUTES]",),
        ),
    ),
)

#: CoT and Standard give only the verdict on FEVER (the paper), so they are not derived from the
#: script's search-and-lookup actions but written here
VERDICT_REPLIES: dict[str, list[dict[str, Any]]] = {
    "cot": [{"think": SCRIPT.plan_thought, "actions": ["finish[REFUTES]"]}],
    "standard": [{"actions": ["finish[REFUTES]"]}],
}


def page_html(text: str) -> str:
    """A Wikipedia-shaped article answer holding ``text`` as one paragraph."""
    return f'<html><body><div id="mw-content-text"><p>{html.escape(text)}</p></div></body></html>'


class DemoSource:
    """The demonstration's Wikipedia: its one page, answered without any request."""

    def __init__(self, base_url: str = DEFAULT_WIKIPEDIA_URL) -> None:
        self.pages = {search_url(base_url, ENTITY): page_html(PAGE)}

    def fetch(self, url: str) -> str:
        """The page for the demonstration's search; WikiError for anything else (the script strays)."""
        try:
            return self.pages[url]
        except KeyError:
            raise WikiError("snapshot_miss", f"the FEVER demonstration answers only its own search, not {url}") from None


def demonstration_env(max_steps: int = DEFAULT_MAX_STEPS, *, verdict_only: bool = False) -> FeverEnvironment:
    """A fresh environment of the demonstration's claim."""
    env = FeverEnvironment(
        CLAIM, DemoSource(), wikipedia_url=DEFAULT_WIKIPEDIA_URL, max_steps=max_steps, verdict_only=verdict_only
    )
    env.instance_id = f"fever-demo/{CLAIM.id}"
    env.split = "train"
    return env


def demonstration_for(max_steps: int = DEFAULT_MAX_STEPS, *, verdict_only: bool = False) -> Demonstration:
    """The shared demonstration, its rules as the episode's (``verdict_only`` for CoT/Standard)."""
    name = f"fever-{CLAIM.id}" + ("-verdict-only" if verdict_only else "") + f"-cap{max_steps}"
    return Demonstration(
        name=name,
        make_env=lambda: demonstration_env(max_steps, verdict_only=verdict_only),
        replies=VERDICT_REPLIES,
        script=SCRIPT,
    )
