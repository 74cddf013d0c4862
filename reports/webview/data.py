"""The viewer's data layer under one name (``D`` in server.py and pages.py): what each page reads, re-exported.

Each job has its own module: :mod:`~reports.webview.snapshot` (one locked-down connection with the
episode list and search column), :mod:`~reports.webview.search` (the search column, read once per
part file), :mod:`~reports.webview.catalog` (the current snapshot, rebuilt in a background thread
when part files change), :mod:`~reports.webview.listquery` (the episode list's URL parameters,
checked), and the pages' SQL: :mod:`~reports.webview.runs`, :mod:`~reports.webview.episodes`,
:mod:`~reports.webview.compare`. Nothing is written anywhere: the run folders stay untouched.
"""

from __future__ import annotations

from reports.webview.catalog import Catalog
from reports.webview.compare import Comparison, compare, compare_choices
from reports.webview.episodes import Episode, EpisodePage, call_window, episode, episode_list, find_episode
from reports.webview.errors import BadRequest
from reports.webview.listquery import MAX_QUERY_CHARS, PAGE_SIZES, SORTABLE, ListQuery, parse_list_query
from reports.webview.runs import redact_spec, run_spec, runs
from reports.webview.search import SearchIndex
from reports.webview.snapshot import FILTERS, SEARCH_CACHE, Snapshot, build_snapshot

__all__ = [
    "FILTERS",
    "MAX_QUERY_CHARS",
    "PAGE_SIZES",
    "SEARCH_CACHE",
    "SORTABLE",
    "BadRequest",
    "Catalog",
    "Comparison",
    "Episode",
    "EpisodePage",
    "ListQuery",
    "SearchIndex",
    "Snapshot",
    "build_snapshot",
    "call_window",
    "compare",
    "compare_choices",
    "episode",
    "episode_list",
    "find_episode",
    "parse_list_query",
    "redact_spec",
    "run_spec",
    "runs",
]
