"""What the notebooks' loop sent, and a Wikipedia that answers as it answered them, rebuilt from their printed runs.

:func:`expected_calls` rebuilds, from one printed episode (:mod:`.notebook_runs`) and the loop's
rules as cell 4 of React.ipynb / baseline_act.ipynb writes them, every request the loop made
(its message list and stop list) with the reply it got. The rules are restated here, independently
of ``recap/baselines/notebook_loop.py``, so a test comparing the two can fail: the demonstration is
``fever.json``'s value under the cell's key, round ``i`` sends ``Thought i:`` / ``Action i:`` (the
question before it on round 1, the cell's final-round sentence on round 10), the re-ask is ``Thought
i: <first line>\\nAction i:`` with stop ``["\\n"]``, and each round leaves ``step_str`` as one
assistant message.

:func:`routes` builds answers for :class:`workers.envs.fever.standin.StandIn` from the printed
observations: a search-result list for "Could not find X. Similar: [...]." (a disambiguation page
first where the release searched ``[X]``), an article whose first five sentences are the printed
ones (plus the sentences the printed lookups found) for a page.
"""

from __future__ import annotations

import ast
import html
import json
import re
from dataclasses import dataclass
from urllib.parse import parse_qs, urlsplit

from tests.workers.envs.fever.notebook_runs import FEVER, NOTEBOOKS, Episode, Step
from workers.envs.fever.standin import Answer
from workers.envs.fever.wiki import search_url

#: the JSON key of each notebook's demonstration (cell 4: ``prompt_dict[...]``)
PROMPT_KEYS = {"react": "webthink_simple3", "act": "webact_simple3"}
ROUNDS = 10


@dataclass(frozen=True)
class Call:
    messages: tuple[tuple[str, str], ...]
    stop: tuple[str, ...]
    reply: str

    def as_json(self) -> str:
        return json.dumps(
            {"messages": [{"role": r, "content": c} for r, c in self.messages], "stop": list(self.stop), "reply": self.reply}
        )


def demonstration(method: str) -> str:
    return json.loads((FEVER / "prompts" / "fever.json").read_text(encoding="utf-8-sig"))[PROMPT_KEYS[method]]


def final_sentence(method: str) -> str:
    """The literal the cell puts before round 10's label (``if i == 10: prompt = '...' + prompt``)."""
    cells = json.loads((FEVER / NOTEBOOKS[method]).read_text(encoding="utf-8-sig"))["cells"]
    source = "".join(cells[4]["source"])
    found = re.search(r"if i == 10:\n\s+prompt = ('[^\n]*') \+ prompt", source)
    assert found is not None, "the final-round line is not in cell 4"
    return ast.literal_eval(found.group(1))


def expected_calls(method: str, episode: Episode, demo: str, final: str) -> list[Call]:
    """Every request of one printed episode, as the notebook's loop built it, with its reply."""
    label = "Thought" if method == "react" else "Action"
    history: list[tuple[str, str]] = [("user", demo)]
    question = f"Claim: {episode.claim}"
    calls: list[Call] = []
    for i, step in enumerate(episode.steps, 1):
        prompt = f"{label} {i}:"
        if i == 1:
            prompt = question + "\n" + prompt
        if i == ROUNDS:
            prompt = final + prompt
        history.append(("user", prompt))
        calls.append(Call(tuple(history), (f"\nObservation {i}:",), step.calls[0].reply))
        if step.bad:
            history.append(("user", f"Thought {i}: {step.thought}\nAction {i}:"))
            calls.append(Call(tuple(history), ("\n",), step.calls[1].reply))
        history.append(("assistant", step_str(i, step)))
    return calls


def step_str(i: int, step: Step) -> str:
    body = f"Action {i}: {step.action}\nObservation {i}: {step.observation}\n"
    return body if step.thought is None else f"Thought {i}: {step.thought}\n" + body


# -- the Wikipedia stand-in's pages ---------------------------------------------------------------


def _doc(inner: str) -> str:
    # no navigation or footer lists: the release reads every <ul> of an answer into the page
    return f'<!DOCTYPE html>\n<html><body><div class="mw-parser-output">{inner}</div></body></html>\n'


def results_page(titles: list[str]) -> str:
    items = "".join(
        f'<li><div class="mw-search-result-heading"><a href="/wiki/x">{html.escape(_escape(t))}</a></div></li>' for t in titles
    )
    return _doc(f'<ul class="mw-search-results">{items}</ul>')


def disambiguation_page(entity: str) -> str:
    return _doc(f"<p>{html.escape(entity)} may refer to:</p>")


def _escape(text: str) -> str:
    """Text the release's ``clean_str`` turns back into ``text`` (a backslash doubled)."""
    return text.replace("\\", "\\\\")


def article(sentences: list[str]) -> str:
    """One paragraph whose ". "-separated sentences are ``sentences`` (each ends with ".")."""
    return _doc(f"<p>{html.escape(_escape('. '.join(s[:-1] for s in sentences)))}</p>")


def page_sentences(observation: str) -> list[str]:
    """The sentences a page observation shows (the inverse of joining them by spaces)."""
    if not observation:
        return []
    assert observation.endswith("."), observation[-80:]
    return [piece + "." for piece in observation[:-1].split(". ")]


_NOT_FOUND = re.compile(r"^Could not find (.*)\. Similar: (\[.*\])\.$", re.S)
_RESULT = re.compile(r"^\(Result (\d+) / (\d+)\) (.*)$", re.S)


def _bracketed(action: str, verb: str) -> str | None:
    action = action.strip()
    if action.startswith(verb + "[") and action.endswith("]"):
        return action[len(verb) + 1 : -1]
    return None


def served_key(entity: str) -> str:
    """The ``search`` value the stand-in receives for ``entity``: the release sends it unencoded
    but for spaces (wikienv.py:99-100), so ``A&E`` reaches the site as ``A``."""
    return parse_qs(urlsplit(search_url("http://standin", entity)).query, keep_blank_values=True).get("search", [""])[0]


def routes(episodes: list[Episode]) -> dict[str, list[Answer]]:
    """The stand-in's answers by search string, for every search the printed runs made."""
    pages: dict[str, list[str]] = {}
    out: dict[str, list[Answer]] = {}
    for episode in episodes:
        current: str | None = None
        for step in episode.steps:
            said = step.action[0].lower() + step.action[1:]
            entity = _bracketed(said, "search")
            keyword = _bracketed(said, "lookup")
            obs = step.observation
            if entity is not None:
                found = _NOT_FOUND.match(obs)
                if found is not None:
                    titles = ast.literal_eval(found.group(2))
                    if found.group(1) == f"[{entity}]":
                        out[served_key(entity)] = [Answer(body=disambiguation_page(entity))]
                        out[served_key(f"[{entity}]")] = [Answer(body=results_page(titles))]
                    else:
                        out[served_key(entity)] = [Answer(body=results_page(titles))]
                else:
                    current = served_key(entity)
                    pages.setdefault(current, page_sentences(obs))
            elif keyword is not None and current is not None:
                result = _RESULT.match(obs)
                if result is not None:
                    sentences = pages[current]
                    if result.group(3) not in sentences:
                        sentences.append(result.group(3))
                    n = int(result.group(2))
                    filler = 0
                    while sum(keyword.lower() in s.lower() for s in sentences) < n:
                        filler += 1
                        sentences.append(f"Another line on {keyword} number {filler}.")
    for entity, sentences in pages.items():
        out[entity] = [Answer(body=article(sentences))]
    return out
