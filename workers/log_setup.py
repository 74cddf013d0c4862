"""One logging set-up for every process of a run: the CLI's and each Ray actor's.

Why: modules log through ``logging.getLogger(__name__)`` (diagnostics: retries, restarts, caps,
recovered logs) and never print; this module decides where those lines go. The CLI calls
:func:`configure` with ``--log-level``; the level travels to the Ray actors in the
``RECAP_LOG_LEVEL`` environment variable (:mod:`pipeline.raysetup`), and each actor calls
:func:`configure_from_env` when it starts, so an actor's lines land in Ray's worker log files at
the level the user asked for. Output that *is* the command's result (tables, reports, progress)
is not logging and does not go through here.
"""

from __future__ import annotations

import logging
import os
import sys

#: the environment variable that carries the level to Ray workers
LEVEL_VAR = "RECAP_LOG_LEVEL"
LEVELS = ("debug", "info", "warning", "error")
DEFAULT_LEVEL = "warning"
_FORMAT = "recap %(levelname)s %(name)s: %(message)s"
#: our packages: the loggers ``--log-level`` governs. Third-party loggers (asyncio, litellm,
#: httpx, Ray) keep their own set-up, so raising our level never floods the terminal with theirs.
PACKAGES = ("recap", "workers", "pipeline", "schemas", "reports")


def configure(level: str = DEFAULT_LEVEL) -> None:
    """Send our packages' log records at ``level`` and above to stderr, one line each, and
    export the level for Ray workers started afterwards."""
    name = level.lower()
    if name not in LEVELS:
        raise ValueError(f"unknown log level {level!r}; one of {', '.join(LEVELS)}")
    numeric = getattr(logging, name.upper())
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(logging.Formatter(_FORMAT))
    handler._recap = True  # type: ignore[attr-defined]  # ours to replace on the next configure()
    for package in PACKAGES:
        logger = logging.getLogger(package)
        for h in [h for h in logger.handlers if getattr(h, "_recap", False)]:
            logger.removeHandler(h)
        logger.addHandler(handler)
        logger.setLevel(numeric)
    os.environ[LEVEL_VAR] = name


def configure_from_env() -> None:
    """In a Ray actor: the level the driver was started with (``RECAP_LOG_LEVEL``), if any."""
    level = os.environ.get(LEVEL_VAR)
    if level and level.lower() in LEVELS:
        configure(level)
