"""One chat call through litellm to the test's fake server, no retries: what the tests of our
litellm and SDK hooks make and then inspect."""

from __future__ import annotations

import asyncio
from typing import Any

from workers.llm.litellm_setup import get_litellm


def fake_call(url: str, model: str = "openai/fake-gpt", content: str = "hello") -> Any:
    """litellm's reply to one user message ``content`` sent to ``model`` at ``url``."""
    return asyncio.run(
        get_litellm().acompletion(
            model=model,
            api_base=url,
            api_key="k",
            messages=[{"role": "user", "content": content}],
            max_tokens=20,
            num_retries=0,
            max_retries=0,
        )
    )
