"""Test doubles shared by the test packages (not part of the product): the offline expert as an
LLM client (:mod:`.offline_expert_client`), model requests and a fake key (:mod:`.llm_requests`),
agent episodes through the gateway (:mod:`.agent_episodes`) and a known run folder
(:mod:`.known_run`). The loopback OpenAI-compatible server with quotas and injected faults is a
labelled test double of the product, :mod:`workers.llm.offline.fake_server`, so ``bench/`` can
use it without importing anything from ``tests/``."""
