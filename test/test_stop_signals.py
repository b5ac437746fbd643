"""StopSignals: a stop signal asks to stop; later ones never interrupt the clean-up."""

import os
import signal
import time

import pytest

from maglev_ros.stop_signals import StopSignals


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_first_signal_requests_stop_and_later_ones_are_only_counted(signum):
    previous = signal.getsignal(signum)
    cleaned = False
    with StopSignals() as stop:
        assert not stop.requested and stop.exit_status == 0
        os.kill(os.getpid(), signum)
        assert stop.event.wait(5.0)
        for _ in range(200):  # a flood during the clean-up: no exception, no recursion
            os.kill(os.getpid(), signum)
        time.sleep(0.05)
        cleaned = True
    assert cleaned
    assert stop.signum == signum and stop.exit_status == 128 + signum
    assert stop.received >= 2
    # after a stop the process is on its way out: these signals stay ignored
    assert signal.getsignal(signum) == signal.SIG_IGN
    signal.signal(signum, previous)


def test_handlers_restored_when_no_signal_came():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    with StopSignals() as stop:
        assert signal.getsignal(signal.SIGHUP) != before[signal.SIGHUP]
    assert not stop.requested
    assert {s: signal.getsignal(s) for s in before} == before
