"""The one error of the viewer's data layer: a request it refuses, with the HTTP status to answer."""

from __future__ import annotations

from reports.views import ReportError


class BadRequest(ReportError):
    """A request the viewer refuses (unknown filter value, page, episode ...): a 4xx, one line."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status
