"""The viewer's pages as HTML strings under one name (``pages`` in server.py): each page's module, re-exported.

Server-rendered on purpose: every page is a plain GET with its state in the URL (filters, sort,
page, search), so a page can be bookmarked, linked from the report and read by a test with
``chromium --dump-dom``; the small script in ``static/app.js`` only adds conveniences (filters
apply on change, a call's window opens in place, expand/collapse the whole tree).

Modules: :mod:`~reports.webview.layout` (the frame and formats), :mod:`~reports.webview.runs_html`,
:mod:`~reports.webview.list_html`, :mod:`~reports.webview.episode_html`,
:mod:`~reports.webview.compare_html`.
"""

from __future__ import annotations

from reports.webview.compare_html import MAX_DISCORDANT, compare_page, compare_tests_note
from reports.webview.episode_html import (
    calls_html,
    episode_page,
    messages_html,
    observation_diff,
    steps_html,
    tree_html,
    window_fragment,
    window_page,
)
from reports.webview.layout import NAV, episode_url, error_page, layout, url
from reports.webview.list_html import episodes_page
from reports.webview.runs_html import runs_page, spec_page

__all__ = [
    "MAX_DISCORDANT",
    "NAV",
    "calls_html",
    "compare_page",
    "compare_tests_note",
    "episode_page",
    "episode_url",
    "episodes_page",
    "error_page",
    "layout",
    "messages_html",
    "observation_diff",
    "runs_page",
    "spec_page",
    "steps_html",
    "tree_html",
    "url",
    "window_fragment",
    "window_page",
]
