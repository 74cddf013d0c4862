"""The episode list's URL parameters (filters, search, sort, page), checked: anything else is a 400."""

from __future__ import annotations

from dataclasses import dataclass

from reports.webview.errors import BadRequest
from reports.webview.snapshot import FILTERS, Snapshot

#: columns the list may be sorted by (the URL names them; nothing else reaches the SQL)
SORTABLE = (
    "episode_id",
    "run_id",
    "model_label",
    "arm",
    "label",
    "env_split",
    "task",
    "instance_id",
    "sampling_seed",
    "attempt",
    "end_reason",
    "mode",
    "success",
    "steps",
    "llm_calls",
    "cost_usd",
    "wall_s",
    "ended_at",
)
PAGE_SIZES = (25, 50, 100, 200)
#: the longest search text accepted (a phrase, not a document)
MAX_QUERY_CHARS = 200


@dataclass(frozen=True)
class ListQuery:
    """The episode list's checked URL parameters: column filters, a message search ``q``, sort column and
    direction, page (1-based) and page size, and whether only the counted (latest) row of each unit is shown."""

    filters: dict[str, str]
    q: str = ""
    sort: str = "episode_id"
    desc: bool = False
    page: int = 1
    per: int = 50
    latest: bool = False


def parse_list_query(params: dict[str, list[str]], snap: Snapshot) -> ListQuery:
    """The list's URL parameters, checked: unknown names, values or pages are a 400."""
    known = {p for p, _ in FILTERS} | {"q", "sort", "dir", "page", "per", "latest"}
    unknown = sorted(set(params) - known)
    if unknown:
        raise BadRequest(f"unknown parameter(s): {', '.join(unknown)}")
    one = {k: v[-1] for k, v in params.items()}
    filters: dict[str, str] = {}
    for param, col in FILTERS:
        value = one.get(param, "")
        if value == "":
            continue
        if col not in snap.columns:
            raise BadRequest(f"filter {param!r} is not available for these runs")
        if param == "success":
            if value not in ("true", "false"):
                raise BadRequest("success must be true or false")
        elif value not in {str(v) for v in snap.options.get(param, [])}:
            raise BadRequest(f"no episode has {param} = {value!r}")
        filters[param] = value
    q = " ".join(one.get("q", "").split())
    if len(q) > MAX_QUERY_CHARS:
        raise BadRequest(f"search text longer than {MAX_QUERY_CHARS} characters")
    sort = one.get("sort", "episode_id") or "episode_id"
    if sort not in SORTABLE or (sort not in snap.columns):
        raise BadRequest(f"cannot sort by {sort!r}")
    direction = one.get("dir", "asc") or "asc"
    if direction not in ("asc", "desc"):
        raise BadRequest("dir must be asc or desc")
    try:
        page = int(one.get("page", "1") or "1")
        per = int(one.get("per", "50") or "50")
    except ValueError:
        raise BadRequest("page and per must be whole numbers") from None
    if page < 1 or page > 1_000_000:
        raise BadRequest("page must be between 1 and 1000000")
    if per not in PAGE_SIZES:
        raise BadRequest(f"per must be one of {', '.join(map(str, PAGE_SIZES))}")
    latest = one.get("latest", "") in ("1", "true")
    return ListQuery(filters, q, sort, direction == "desc", page, per, latest)
