"""The progress line of a slow step (issue 36 item 6): said once the step passes its threshold, with
how long it took; nothing for a quick step, and nothing on a stderr that is not a terminal (a
refusal stays one line there)."""

from __future__ import annotations

import io
import re
import time

import pytest

from pipeline.cli.notice import slow_notice


def test_a_slow_step_is_said_with_how_long_it_took() -> None:
    out = io.StringIO()
    with slow_notice("measuring 3 instances", after_s=0.05, stream=out):
        time.sleep(0.4)
    lines = out.getvalue().splitlines()
    assert lines[0] == "recap: measuring 3 instances ..."
    assert re.fullmatch(
        r"recap: measuring 3 instances: done in 0\.[4-9] s|recap: measuring 3 instances: done in [1-9]\.\d s", lines[1]
    )
    assert len(lines) == 2


def test_a_quick_step_says_nothing() -> None:
    out = io.StringIO()
    with slow_notice("listing", after_s=5.0, stream=out):
        pass
    time.sleep(0.05)
    assert out.getvalue() == ""


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize("tty", [True, False])
def test_stderr_hears_it_only_when_it_is_a_terminal(monkeypatch: pytest.MonkeyPatch, tty: bool) -> None:
    err = _Tty() if tty else io.StringIO()
    monkeypatch.setattr("sys.stderr", err)
    with slow_notice("checking the models", after_s=0.05):
        time.sleep(0.3)
    assert (err.getvalue().splitlines()[:1] == ["recap: checking the models ..."]) if tty else err.getvalue() == ""
