"""Benchmark environments behind :class:`recap.env.Environment`, found through the registry."""
