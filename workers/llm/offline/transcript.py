"""TEST DOUBLE ``offline/replay`` over a transcript file: recorded replies keyed by the exact request.

Why beside the run-folder replay (:mod:`.replay`): a run recorded *outside* recap-eval (the
authors' printed notebook runs, rebuilt by a test) has no ``llm_calls``/``messages`` tables. A
transcript is a JSON-lines file, one call a line: ``{"messages": [{"role", "content"}, ...],
"stop": [...], "reply": "..."}``. A request is answered only when its whole message list *and*
its stop list equal a recorded call's, so a request built differently from the recorded one gets
no answer (a :class:`~.replay.ReplayError`, the call fails) instead of a plausible reply.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from workers.llm.fingerprint import messages_fingerprint
from workers.llm.offline.replay import ReplayError

#: the file name ending that makes ``api_base`` a transcript rather than a run folder
SUFFIX = ".jsonl"


def request_key(messages: Sequence[dict[str, str]], stop: Sequence[str]) -> str:
    """The hash of a request's (role, content) list and its stop list."""
    payload = json.dumps([messages_fingerprint(messages), list(stop)], ensure_ascii=False)
    return hashlib.sha256(payload.encode("utf-8")).hexdigest()


@dataclass
class TranscriptIndex:
    """The replies of one transcript file by :func:`request_key`."""

    path: Path
    replies: dict[str, str] = field(default_factory=dict)

    @classmethod
    def load(cls, path: Path | str) -> TranscriptIndex:
        index = cls(Path(path))
        try:
            lines = index.path.read_text(encoding="utf-8").splitlines()
        except OSError as exc:
            raise ReplayError(f"offline/replay: cannot read transcript {index.path}: {exc}") from None
        for n, line in enumerate(lines, 1):
            try:
                row = json.loads(line)
                key = request_key(row["messages"], row.get("stop") or [])
                reply = str(row["reply"])
            except (ValueError, KeyError, TypeError) as exc:
                raise ReplayError(f"offline/replay: {index.path.name} line {n} is not a recorded call ({exc})") from None
            index.replies[key] = reply
        return index

    def answer(self, messages: Sequence[dict[str, str]], stop: Sequence[str]) -> str:
        key = request_key(messages, stop)
        if key not in self.replies:
            raise ReplayError(
                f"offline/replay: no call in {self.path.name} with this message list and stop list "
                f"({len(messages)} messages, stop {list(stop)!r})"
            )
        return self.replies[key]


def is_transcript(api_base: str) -> bool:
    """Whether ``api_base`` names a transcript file."""
    return api_base.endswith(SUFFIX) and Path(api_base).is_file()


def transcript_index(path: str) -> TranscriptIndex:
    """The index of ``path``, loaded once per process."""
    return _load(str(Path(path).resolve()))


@cache
def _load(resolved: str) -> TranscriptIndex:
    """The index of the resolved path, read the first time it is asked for (a failed read is not
    kept, so the next call tries again)."""
    return TranscriptIndex.load(resolved)
