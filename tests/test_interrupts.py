"""DeferredStop: the first Ctrl-C / SIGTERM waits for the loop's safe point, a second acts at once."""

from __future__ import annotations

import os
import signal

import pytest

from ohra.interrupts import DeferredStop


def test_the_first_signal_only_asks_and_stop_then_raises_keyboard_interrupt(terminal_sigint, capsys):
    with DeferredStop("the test loop", at="after this line") as stop:
        os.kill(os.getpid(), signal.SIGINT)
        assert stop.requested and stop.signum == signal.SIGINT  # no KeyboardInterrupt yet
        with pytest.raises(KeyboardInterrupt):
            stop.stop()
    assert "stopping the test loop after this line" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_second_signal_acts_at_once(terminal_sigint):
    with pytest.raises(KeyboardInterrupt):
        with DeferredStop(quiet=True):
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
            pytest.fail("the second Ctrl-C did not stop the block")
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_sigterm_is_handed_to_the_handler_it_replaced():
    class Ended(Exception):
        pass

    def ended(*_):
        raise Ended

    previous = signal.signal(signal.SIGTERM, ended)
    try:
        with DeferredStop(quiet=True) as stop:
            os.kill(os.getpid(), signal.SIGTERM)
            assert stop.requested
            with pytest.raises(Ended):
                stop.stop()
        assert signal.getsignal(signal.SIGTERM) is ended
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_no_signal_no_stop_and_an_ignored_sigint_stays_ignored():
    with DeferredStop() as stop:
        stop.stop()  # nothing came: nothing happens
    inherited = signal.signal(signal.SIGINT, signal.SIG_IGN)  # nohup, a background job, a pool worker
    try:
        with DeferredStop(quiet=True) as stop:
            os.kill(os.getpid(), signal.SIGINT)
            assert not stop.requested
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, inherited)


def test_a_previous_handler_that_returns_lets_the_loop_go_on_and_the_next_signal_is_deferred_again():
    """A scheduler's "bypass" SIGTERM handler returns: the trainer saved and went on, but the next step's check
    still saw the old request and, its handlers already put back, died by the default action."""
    seen = []
    previous = signal.signal(signal.SIGTERM, lambda *_: seen.append("bypassed"))
    try:
        with DeferredStop(quiet=True) as stop:
            os.kill(os.getpid(), signal.SIGTERM)
            stop.stop()  # the bypass handler returns: go on
            assert seen == ["bypassed"] and not stop.requested
            os.kill(os.getpid(), signal.SIGTERM)  # deferred again, not the default end
            assert stop.requested and seen == ["bypassed"]
            stop.stop()
            assert seen == ["bypassed", "bypassed"]
    finally:
        signal.signal(signal.SIGTERM, previous)
