"""SIGINT / SIGTERM inside ``stop_at_safe_point`` ask for a stop instead of raising; handlers restored after."""

from __future__ import annotations

import os
import signal

import pytest

from setdiff_bench.runtime.interrupts import STOP_SIGNALS, stop_at_safe_point, stop_requested


@pytest.mark.parametrize("signum", STOP_SIGNALS)
def test_signal_sets_the_request_and_handlers_come_back(signum: int) -> None:
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    with stop_at_safe_point():
        assert not stop_requested()
        os.kill(os.getpid(), signum)
        assert stop_requested()
    assert not stop_requested()
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == before


def test_a_second_signal_interrupts_at_once() -> None:
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # Python's own Ctrl-C behaviour
    try:
        _second_signal_and_after()
    finally:
        signal.signal(signal.SIGINT, previous)


def _second_signal_and_after() -> None:
    with pytest.raises(KeyboardInterrupt), stop_at_safe_point():
        os.kill(os.getpid(), signal.SIGINT)
        os.kill(os.getpid(), signal.SIGINT)
    assert not stop_requested()
    with pytest.raises(KeyboardInterrupt):  # outside the block Ctrl-C raises as usual
        os.kill(os.getpid(), signal.SIGINT)
