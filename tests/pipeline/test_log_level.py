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
def _restore_logging(monkeypatch):
    monkeypatch.delenv(log_setup.LEVEL_VAR, raising=False)
    root = logging.getLogger()
    level, handlers = root.level, list(root.handlers)
    yield
    root.setLevel(level)
    root.handlers[:] = handlers


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


def test_configure_sets_the_root_level_and_exports_it_for_ray_workers(capsys):
    log_setup.configure("info")
    assert logging.getLogger().level == logging.INFO
    assert os.environ[log_setup.LEVEL_VAR] == "info"
    assert runtime_env()["env_vars"][log_setup.LEVEL_VAR] == "info"
    EventBuffer().add("unit_failed", severity="error", unit_id="u1", episode_id="u1-0", attempt=0)
    assert capsys.readouterr().err == (
        "recap INFO pipeline.events: event unit_failed (error) unit u1 episode u1-0 {'attempt': 0}\n"
    )
    log_setup.configure("warning")  # a second call replaces the handler, no duplicate lines
    logging.getLogger("pipeline.x").warning("once")
    assert capsys.readouterr().err == "recap WARNING pipeline.x: once\n"
    assert logging.getLogger("httpx").level == logging.WARNING


def test_an_actor_takes_the_level_from_the_environment(monkeypatch):
    monkeypatch.setenv(log_setup.LEVEL_VAR, "debug")
    log_setup.configure_from_env()
    assert logging.getLogger().level == logging.DEBUG
    monkeypatch.setenv(log_setup.LEVEL_VAR, "nonsense")  # ignored: an actor never fails on it
    log_setup.configure_from_env()
    assert logging.getLogger().level == logging.DEBUG
