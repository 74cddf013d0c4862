"""litellm's per-call success-logging task runs only when something listens
(:mod:`workers.llm.success_logging`): a call through the fake server with no callback builds no
payload, and a registered callback still gets the call's success event with its usage."""

from __future__ import annotations

import asyncio

from tests.workers.llm.fake_calls import fake_call
from workers.llm import success_logging
from workers.llm.litellm_setup import get_litellm

litellm = get_litellm()


def test_no_task_without_listeners_and_events_with_one(fake_server, monkeypatch) -> None:
    from litellm.integrations.custom_logger import CustomLogger
    from litellm.litellm_core_utils import litellm_logging

    assert success_logging.install(litellm) is True
    assert success_logging.nobody_listens(litellm)
    built: list[object] = []
    real = litellm_logging.Logging.async_success_handler

    async def spy(self, *args, **kwargs):
        built.append(self)
        return await real(self, *args, **kwargs)

    monkeypatch.setattr(litellm_logging.Logging, "async_success_handler", spy)
    server = fake_server()
    resp = fake_call(server.base_url)
    assert resp.choices[0].message.content  # the call itself is unchanged
    assert resp._hidden_params.get("litellm_call_id")  # and its hidden params are set
    assert built == []  # nobody listens: no payload task

    events: list[dict] = []

    class Listener(CustomLogger):
        async def async_log_success_event(self, kwargs, response_obj, start_time, end_time):
            events.append(kwargs.get("standard_logging_object") or {})

    listener = Listener()
    monkeypatch.setattr(litellm, "callbacks", [listener])
    assert not success_logging.nobody_listens(litellm)

    async def call_and_drain() -> None:
        await litellm.acompletion(
            model="openai/fake-gpt",
            api_base=server.base_url,
            api_key="k",
            messages=[{"role": "user", "content": "hello again"}],
            max_tokens=20,
            num_retries=0,
            max_retries=0,
        )
        for _ in range(50):  # the logging task runs after the call returns
            if events:
                return
            await asyncio.sleep(0.05)

    asyncio.run(call_and_drain())
    assert len(built) == 1
    assert len(events) == 1 and events[0].get("total_tokens", 0) > 0


def test_zero_cost_diagnostic_runs_only_when_read_and_the_cost_is_unchanged(fake_server, monkeypatch) -> None:
    """The diagnostic's price lookup is skipped while nothing reads it; litellm's response_cost (our
    provider_cost_usd) is the same with and without it, for a model litellm prices and for one it
    cannot price (None)."""
    import logging

    from litellm.litellm_core_utils import litellm_logging

    assert success_logging.install_zero_cost_diagnostic(litellm) is True
    findings: list[object] = []
    real = litellm_logging.Logging._zero_cost_finding

    def spy(self, *args, **kwargs):
        findings.append(self)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(litellm_logging.Logging, "_zero_cost_finding", spy)
    for name in success_logging.LISTENER_LISTS:  # an earlier test's listener stays in litellm's own lists
        monkeypatch.setattr(litellm, name, [])
    server = fake_server(cache_rule="none")  # the same usage for every call of the same prompt
    # the fake server answers any model name: one litellm's cost map knows, one it does not
    costs_quiet = [
        fake_call(server.base_url, m, "price me")._hidden_params.get("response_cost")
        for m in ("openai/gpt-4o-mini", "openai/fake-gpt")
    ]
    assert success_logging.diagnostic_unread(litellm)
    assert findings == []  # nobody reads it: no lookup

    lg = logging.getLogger("LiteLLM")
    quiet_level = lg.level
    lg.setLevel(logging.WARNING)  # now the warning would be logged (setLevel clears the logger's level cache)
    try:
        assert not success_logging.diagnostic_unread(litellm)
        costs_read = [
            fake_call(server.base_url, m, "price me")._hidden_params.get("response_cost")
            for m in ("openai/gpt-4o-mini", "openai/fake-gpt")
        ]
    finally:
        lg.setLevel(quiet_level)
    assert len(findings) == 2  # read: each reply's diagnostic ran
    assert costs_quiet == costs_read
    assert costs_quiet[0] is not None and costs_quiet[0] > 0 and costs_quiet[1] is None
