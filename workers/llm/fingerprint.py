"""Stable hashes of chat messages and requests (response cache, replay matching).

Why canonical JSON + SHA-256: the same messages must hash the same in every process and run
(Python's ``hash`` is salted per process), and only role and content matter.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False, default=str)


def messages_fingerprint(messages: Sequence[Mapping[str, Any]]) -> str:
    """The hex SHA-256 of the messages' (role, content) pairs in order (other message fields are
    ignored): how offline/replay matches a request."""
    return hashlib.sha256(_canonical([[str(m["role"]), str(m["content"])] for m in messages]).encode()).hexdigest()


def request_fingerprint(model: str, params: Mapping[str, Any], messages: Sequence[Mapping[str, Any]]) -> str:
    """Key of the response cache: model, generation settings and messages."""
    return hashlib.sha256(
        _canonical({"model": model, "params": dict(params), "messages": messages_fingerprint(messages)}).encode()
    ).hexdigest()
