"""Test doubles that are not part of the product: the loopback OpenAI-compatible server with
quotas and injected faults (:mod:`tests.doubles.fake_server`), used by the gateway, chaos and
pipeline tests and by ``bench/``. (The offline models a sweep can name, ``offline/expert`` and
friends, are product code in :mod:`workers.llm.offline`: users run them.)"""
