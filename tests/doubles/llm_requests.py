"""Model requests as the agents build them, and a fake API key, for the gateway and model-client tests."""

from __future__ import annotations

from recap.llm import ChatMessage, LLMRequest

#: a fake API key; tests check it never reaches a written file
FAKE_KEY = "sk-test-FAKEKEY-a1b2c3d4e5f6g7h8"
FAKE_KEY_ENV = "RECAP_TEST_FAKE_KEY"


def make_request(
    i: int, content: str | None = None, *, episode: str = "ep", hints=None, max_tokens: int | None = None, window=None
) -> LLMRequest:
    """The ``i``-th task request of an episode, one user message, with the given hints and window."""
    return LLMRequest(
        messages=(ChatMessage("user", content if content is not None else f"request number {i}"),),
        episode_id=episode,
        call_index=i,
        purpose="task",
        window_seqs=tuple(window) if window is not None else (i,),
        node_id=0,
        response_seq=i + 1,
        max_tokens=max_tokens,
        hints=hints or {},
    )
