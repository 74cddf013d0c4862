"""Sandboxes for coding environments: one isolated copy of a repository per episode, where a
model's shell commands run under limits (see :mod:`workers.sandbox.base`)."""
