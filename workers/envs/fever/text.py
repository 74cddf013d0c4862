"""How a Wikipedia search answer becomes FEVER's observation text, exactly as the authors' release does it.

Every function here follows ``fever-recap/hotpotqa/wikienv.py`` and ``fever-recap/hotpotqa/wrappers.py``
of the released repository (GitHub ``ReCAP-Stanford/ReCAP``), line by line, because the paper's
numbers were measured on these strings: the HTML is parsed with BeautifulSoup's ``html.parser``,
search-result headings become "Could not find ..." with the first five titles, a page is the text of
its ``<p>`` and ``<ul>`` elements, an observation is its first five ". "-separated sentences, and
the answer is compared after the SQuAD-style normalisation. Pure functions on strings; no I/O.
"""

from __future__ import annotations

import re
import string
from dataclasses import dataclass

from bs4 import BeautifulSoup

#: the phrase that marks a disambiguation page (wikienv.py:112)
DISAMBIGUATION_MARK = "may refer to:"
#: how many search-result titles the observation lists (wikienv.py:109)
SIMILAR_TITLES = 5
#: how many sentences of a page the observation shows (wikienv.py:87)
PAGE_SENTENCES = 5
NO_MORE_RESULTS = "No more results.\n"  # wikienv.py:144
THOUGHT_ACK = "Nice thought."  # wikienv.py:154


class UnreadableTextError(ValueError):
    """Page text the release's ``clean_str`` cannot decode (a stray backslash escape): the release
    crashes on it, so there is no observation to give."""


def clean_str(text: str) -> str:
    """The release's ``clean_str`` (wikienv.py:10-11): undo backslash escapes, then re-read the bytes
    as UTF-8. Raises UnreadableTextError where the release raises (e.g. ``C:\\Users``)."""
    try:
        return text.encode().decode("unicode-escape").encode("latin1").decode("utf-8")
    except UnicodeError as exc:
        raise UnreadableTextError(f"text the release cannot clean ({type(exc).__name__}: {exc})") from None


@dataclass(frozen=True)
class SearchAnswer:
    """What one search answer holds, as the release reads it (wikienv.py:105-122).

    ``titles``: the search-result headings (cleaned) when the search did not land on a page;
    ``disambiguation``: the page says "may refer to:" (the release searches again for ``[entity]``);
    ``page``: the page text otherwise (paragraphs joined by newlines)."""

    titles: tuple[str, ...] | None
    disambiguation: bool
    page: str | None


def read_search_html(html: str) -> SearchAnswer:
    """Parse one answer of ``/w/index.php?search=`` the way wikienv.py:105-121 does."""
    soup = BeautifulSoup(html, features="html.parser")
    result_divs = soup.find_all("div", {"class": "mw-search-result-heading"})
    if result_divs:  # wikienv.py:107-108: a list of search results, no page
        return SearchAnswer(tuple(clean_str(div.get_text().strip()) for div in result_divs), False, None)
    parts = [p.get_text().strip() for p in soup.find_all("p") + soup.find_all("ul")]  # wikienv.py:111
    if any(DISAMBIGUATION_MARK in p for p in parts):  # wikienv.py:112
        return SearchAnswer(None, True, None)
    page = ""
    for p in parts:  # wikienv.py:115-120: only parts of more than two space-separated words
        if len(p.split(" ")) > 2:
            page += clean_str(p)
            if not p.endswith("\n"):
                page += "\n"
    return SearchAnswer(None, False, page)


def not_found_text(entity: str, titles: tuple[str, ...]) -> str:
    """``Could not find X. Similar: [...].`` with the first five titles as a Python list (wikienv.py:109)."""
    return f"Could not find {entity}. Similar: {list(titles[:SIMILAR_TITLES])}."


def sentences(page: str) -> list[str]:
    """The page's sentences: non-empty stripped lines split at ". ", each given back its final "."
    (wikienv.py:63-70 and 79-86)."""
    paragraphs = [p.strip() for p in page.split("\n") if p.strip()]
    found: list[str] = []
    for p in paragraphs:
        found += p.split(". ")
    return [s.strip() + "." for s in found if s.strip()]


def page_observation(page: str) -> str:
    """The first five sentences joined by spaces (wikienv.py:77-87)."""
    return " ".join(sentences(page)[:PAGE_SENTENCES])


def lookup_sentences(page: str | None, keyword: str) -> list[str]:
    """Sentences containing ``keyword`` case-insensitively; none before any page (wikienv.py:59-74)."""
    if page is None:
        return []
    return [s for s in sentences(page) if keyword.lower() in s.lower()]


def lookup_text(index: int, found: list[str]) -> str:
    """``(Result k / n) sentence`` for the ``index``-th (0-based) match, or the end message (wikienv.py:143-147)."""
    if index >= len(found):
        return NO_MORE_RESULTS
    return f"(Result {index + 1} / {len(found)}) " + found[index]


def invalid_action_text(action: str) -> str:
    """The answer to anything that is not an action (wikienv.py:156); ``action`` is already stripped."""
    return f"Invalid action: {action}"


def finished_text(reward: int) -> str:
    """The observation that ends an episode (wrappers.py:191)."""
    return f"Episode finished, reward = {reward}\n"


def claim_text(claim: str) -> str:
    """The first observation of an episode (wrappers.py:166)."""
    return f"Claim: {claim}"


def leading_entity(claim: str) -> str:
    """The claim's leading run of capitalised words (``Nikolaj Coster-Waldau worked ...`` ->
    ``Nikolaj Coster-Waldau``): what the offline expert searches when the claim cites no page."""
    words: list[str] = []
    for word in claim.split():
        if not word[:1].isupper():
            break
        words.append(word.rstrip(".,;:!?"))
        if word[-1:] in ".,;:!?":
            break
    return " ".join(words)


def normalize_answer(text: str) -> str:
    """Lower-case, drop punctuation, the articles a/an/the and extra spaces (wrappers.py:42-56)."""
    lowered = text.lower()
    no_punct = "".join(ch for ch in lowered if ch not in set(string.punctuation))
    no_articles = re.sub(r"\b(a|an|the)\b", " ", no_punct)
    return " ".join(no_articles.split())


def reward_for(answer: str | None, label: str) -> int:
    """1 when the normalised answer equals the normalised label, else 0; no answer: 0 (wrappers.py:178-184)."""
    if answer is not None and normalize_answer(label) == normalize_answer(answer):
        return 1
    return 0
