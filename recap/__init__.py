"""The ReCAP method and its baselines: pure Python, no Ray, no file or network I/O.

Agents talk to an :class:`recap.env.Environment` and an :class:`recap.llm.LLMClient` and emit
records (``schemas.records``) to a sink callable. Everything that touches processes, files or
the network lives in ``workers/`` and ``pipeline/``.
"""
