"""The frame every viewer page shares (head, navigation, freshness footer) and the escaping and number formats.

Every value from the tables goes through :func:`esc` (:func:`html.escape`): messages and observations
are model output.
"""

from __future__ import annotations

import math
import time
from html import escape
from typing import Any
from urllib.parse import urlencode

from reports.model import format_value
from reports.webview.snapshot import Snapshot

NAV = (("/", "Runs"), ("/episodes", "Episodes"), ("/compare", "Compare"))


def esc(v: Any) -> str:
    """``v`` as HTML text (None as nothing): every value from the tables passes here, messages are model output."""
    return escape("" if v is None else str(v))


def usd(v: Any) -> str:
    """A dollar amount as the report writes it."""
    return format_value("usd", v)


def num(v: Any) -> str:
    """A count or measure with thousands separators (floats to two places); a dash for none."""
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if isinstance(v, float):
        return f"{v:,.2f}"
    return f"{v:,}" if isinstance(v, int) and not isinstance(v, bool) else esc(v)


def url(path: str, **params: Any) -> str:
    """``path`` with ``params`` as its query string; None and "" are left out and booleans spelled true/false, so
    a page's state stays a short, bookmarkable URL."""
    clean = {k: ("true" if v is True else "false" if v is False else v) for k, v in params.items() if v not in (None, "")}
    return path + ("?" + urlencode(clean) if clean else "")


def episode_url(run_id: str, episode_id: str, **extra: Any) -> str:
    """The URL of one episode's page (``extra``: e.g. ``hit``, the message to open at)."""
    return url("/episode", run=run_id, id=episode_id, **extra)


def layout(title: str, body: str, *, page: str, snap: Snapshot | None = None) -> str:
    """A whole page: head, the navigation (``page`` marks the current entry) and ``body``; with ``snap``, a
    footer saying how fresh the data is and how many part files were skipped."""
    nav = "".join(f'<a href="{h}"{" class=current" if h == page else ""}>{t}</a>' for h, t in NAV)
    foot = ""
    if snap is not None:
        foot = (
            f"<footer>Data as of {esc(_clock(snap.built_at))} (refreshed when part files change) · "
            f"{len(snap.run_dirs)} run folder(s), read-only"
            + (f' · <span class="warn">{len(snap.skipped)} unreadable part file(s) skipped</span>' if snap.skipped else "")
            + "</footer>"
        )
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        f'<title>{esc(title)} · recap view</title><link rel="stylesheet" href="/static/app.css">'
        '<script src="/static/app.js" defer></script></head>'
        f'<body data-page="{esc(page.strip("/") or "runs")}"><header><strong>recap view</strong><nav>{nav}</nav></header>'
        f"<main>{body}</main>{foot}</body></html>"
    )


def _clock(ts: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(ts))


def error_page(status: int, message: str) -> str:
    """The page for a refused request: the status and its one-line message."""
    return layout(f"Error {status}", f'<h1>Error {status}</h1><p class="error" id="error">{esc(message)}</p>', page="")
