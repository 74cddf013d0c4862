"""SIGINT/SIGTERM during a session (pipeline.stopping): flags once the loop runs, an interrupt
before it and on the third signal. The whole path through the CLI is in
tests/pipeline/chaos/test_chaos_slow.py (signals.sigint: once, twice; signals.orphans)."""

from __future__ import annotations

import os
import signal

import pytest

from pipeline.cli import main
from pipeline.stopping import StopRequests


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_first_signal_asks_for_a_graceful_stop_the_second_for_now_the_third_raises(sig):
    stop = StopRequests()
    stop.install()
    try:
        stop.arm()
        os.kill(os.getpid(), sig)
        assert (stop.count, stop.graceful, stop.now) == (1, True, False)
        os.kill(os.getpid(), sig)
        assert (stop.count, stop.graceful, stop.now) == (2, True, True)
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), sig)
    finally:
        stop.restore()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_signal_before_the_loop_runs_raises_at_once():
    before = signal.getsignal(signal.SIGTERM)  # SIG_DFL, or ray.init's handler if a test started Ray here
    stop = StopRequests()
    stop.install()
    stop.install()  # again (after ray.init): the first handlers are what restore gives back
    try:
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
    finally:
        stop.restore()
    assert signal.getsignal(signal.SIGTERM) is before


@pytest.mark.parametrize("value", ["0", "-1", "nan", "inf", "soon"])
def test_stop_grace_must_be_a_finite_positive_number(value, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["run", "sweep.yaml", "--stop-grace", value])
    assert exc.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1
    assert err.startswith("recap: error: run: argument --stop-grace: ")


def test_two_deliveries_seen_by_one_handler_call_count_twice():
    """A quick double Ctrl-C while the main thread sits in one blocking call reaches Python as
    one handler call; the wakeup pipe holds a byte per delivery (the first one's byte is written
    here by hand, as the C-level handler writes it), so it counts as two: stop now."""
    stop = StopRequests()
    stop.install()
    try:
        stop.arm()
        assert stop._pipe is not None
        os.write(stop._pipe[1], bytes([signal.SIGINT]))
        os.kill(os.getpid(), signal.SIGINT)
        assert (stop.count, stop.now) == (2, True)
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGTERM)
        assert stop.count == 3
    finally:
        stop.restore()
    assert signal.set_wakeup_fd(-1) == -1  # the wakeup fd given back
