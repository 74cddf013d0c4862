"""--log-level: where diagnostics go, and how the level reaches the Ray workers."""

from __future__ import annotations

import logging
import os

import pytest

from pipeline.cli import _take_log_level, main
from pipeline.errors import PipelineError
from pipeline.events import EventBuffer
from pipeline.raysetup import runtime_env
from workers import log_setup


@pytest.fixture(autouse=True)
def _no_level_in_the_environment(monkeypatch):
    monkeypatch.delenv(log_setup.LEVEL_VAR, raising=False)  # (tests/conftest.py resets the loggers)


@pytest.mark.parametrize(
    "argv, level, rest",
    [
        (["--log-level", "debug", "status", "r"], "debug", ["status", "r"]),
        (["status", "r", "--log-level=info"], "info", ["status", "r"]),
        (["run", "s.yaml", "--log-level", "ERROR", "--workers", "2"], "ERROR", ["run", "s.yaml", "--workers", "2"]),
        (["sql", "r", "--", "--log-level"], None, ["sql", "r", "--", "--log-level"]),
        (["status", "r"], None, ["status", "r"]),
    ],
)
def test_the_option_is_taken_wherever_it_stands(argv, level, rest):
    assert _take_log_level(argv) == level
    assert argv == rest


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--log-level", "loud", "status", "r"], "--log-level: unknown level 'loud'; one of debug, info, warning, error"),
        (["status", "r", "--log-level"], "--log-level needs a level: debug, info, warning, error"),
    ],
)
def test_a_bad_level_is_one_line_and_exit_2(argv, message, capsys):
    with pytest.raises(PipelineError, match="^" + message.replace("(", r"\(") + "$"):
        _take_log_level(list(argv))
    assert main(list(argv)) == 2
    assert capsys.readouterr().err == f"recap: error: {message}\n"


def test_configure_sets_our_packages_level_and_exports_it_for_ray_workers(capsys):
    root_level = logging.getLogger().level
    log_setup.configure("info")
    assert [logging.getLogger(p).level for p in log_setup.PACKAGES] == [logging.INFO] * 5
    assert logging.getLogger().level == root_level  # third-party loggers keep their own set-up
    assert os.environ[log_setup.LEVEL_VAR] == "info"
    assert runtime_env()["env_vars"][log_setup.LEVEL_VAR] == "info"
    EventBuffer().add("unit_failed", severity="error", unit_id="u1", episode_id="u1-0", attempt=0)
    assert capsys.readouterr().err == (
        "recap INFO pipeline.events: event unit_failed (error) unit u1 episode u1-0 {'attempt': 0}\n"
    )
    log_setup.configure("warning")  # a second call replaces the handler, no duplicate lines
    logging.getLogger("pipeline.x").warning("once")
    assert capsys.readouterr().err == "recap WARNING pipeline.x: once\n"
    logging.getLogger("asyncio").error("not ours")  # e.g. a garbage-collected task: not on our stream
    assert "not ours" not in capsys.readouterr().err


def test_an_actor_takes_the_level_from_the_environment(monkeypatch):
    monkeypatch.setenv(log_setup.LEVEL_VAR, "debug")
    log_setup.configure_from_env()
    assert logging.getLogger("workers").level == logging.DEBUG
    monkeypatch.setenv(log_setup.LEVEL_VAR, "nonsense")  # ignored: an actor never fails on it
    log_setup.configure_from_env()
    assert logging.getLogger("workers").level == logging.DEBUG
