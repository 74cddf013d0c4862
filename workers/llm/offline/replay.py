"""TEST DOUBLE ``offline/replay``: the recorded responses of an earlier run, matched by messages.

Why: after changing an agent or a report, rerunning a recorded run through the replay model
shows what changed at zero cost. The run folder is the deployment's ``api_base``. Each
``llm_calls`` row (status ok, with a ``response_seq``) is turned back into its request - the
``messages`` rows of its ``window_seqs`` in order - and its response - the message at
``response_seq``. A request is matched by the SHA-256 of its (role, content) list; when one
window was answered several times, the answer recorded under the same call key is preferred.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from schemas.parts import read_table
from workers.llm.fingerprint import messages_fingerprint


class ReplayError(LookupError):
    """The replay folder cannot be read, or has no recorded answer for a request."""


@dataclass
class ReplayIndex:
    """The replayable calls of one recorded run: responses keyed by the hash of their request's
    messages (see the module docstring); ``answer`` raises ReplayError for a request that was never
    recorded."""

    run_dir: Path
    #: messages hash -> [(call_key, response text), ...] in recorded order
    answers: dict[str, list[tuple[str, str]]] = field(default_factory=dict)

    @classmethod
    def load(cls, run_dir: Path | str) -> ReplayIndex:
        run_dir = Path(run_dir)
        if not (run_dir / "llm_calls").is_dir() or not (run_dir / "messages").is_dir():
            raise ReplayError(f"offline/replay: {run_dir} has no llm_calls/ and messages/ tables to replay")
        messages, _ = read_table(run_dir, "messages")
        calls, _ = read_table(run_dir, "llm_calls")
        text: dict[tuple[str, int], tuple[str, str]] = {}
        for m in messages.select(["episode_id", "seq", "role", "content"]).to_pylist():
            text[(m["episode_id"], m["seq"])] = (m["role"], m["content"])
        index = cls(run_dir)
        for c in calls.select(["episode_id", "call_key", "status", "window_seqs", "response_seq"]).to_pylist():
            if c["status"] != "ok" or c["response_seq"] is None:
                continue
            ep = c["episode_id"]
            try:
                window = [text[(ep, s)] for s in c["window_seqs"]]
                response = text[(ep, c["response_seq"])][1]
            except KeyError:
                continue  # messages of this call were not recorded (killed run): not replayable
            key = messages_fingerprint([{"role": r, "content": t} for r, t in window])
            index.answers.setdefault(key, []).append((c["call_key"], response))
        return index

    def answer(self, messages: list[dict[str, str]], call_key: str) -> str:
        key = messages_fingerprint(messages)
        found = self.answers.get(key)
        if not found:
            raise ReplayError(
                f"offline/replay: no recorded response in {self.run_dir.name} for this request "
                f"(messages hash {key[:12]}, {len(messages)} messages)"
            )
        for recorded_key, text in found:
            if recorded_key == call_key:
                return text
        return found[0][1]


def replay_index(run_dir: str) -> ReplayIndex:
    """The index of ``run_dir``, loaded once per process."""
    return _load(str(Path(run_dir).resolve()))


@cache
def _load(resolved: str) -> ReplayIndex:
    """The index of the resolved path, read the first time it is asked for (a failed read is not
    kept, so the next call tries again)."""
    return ReplayIndex.load(resolved)
