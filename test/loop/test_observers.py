"""Observers never hold the loop up: a slow one drops with a count."""

import threading
import time

import pytest

from maglev_ros.loop import ObserverSet, ObserverThread


def test_a_slow_observer_behind_its_thread_drops_with_a_count_and_never_blocks():
    release, entered = threading.Event(), threading.Event()
    got = []

    def slow(sample):
        entered.set()
        release.wait(5.0)
        got.append(sample)

    with ObserverThread(slow, depth=10) as observer:
        observer(0)
        assert entered.wait(5.0)  # the thread holds sample 0
        started = time.perf_counter()
        for k in range(1, 1000):
            observer(k)
        handed = time.perf_counter() - started
        release.set()
        assert observer.flush(5.0)
    # the thread took the first sample (and waits), 10 more queued: the rest dropped
    assert observer.dropped == 1000 - 11 and observer.delivered == 11
    assert got == list(range(11))
    assert handed < 0.5  # the loop's side only appends (about 1 us a sample)


def test_an_observer_that_raises_is_reported_and_later_samples_are_dropped():
    def broken(sample):
        raise RuntimeError('disk full')

    with ObserverThread(broken) as observer:
        observer(1)
        assert observer.flush(5.0)
        observer(2)
    assert isinstance(observer.error, RuntimeError) and observer.dropped == 1


def test_observer_set_adds_and_removes():
    seen = []
    observers = ObserverSet()
    assert not observers
    observers.add(seen.append)
    observers(1)
    observers.remove(seen.append)
    observers(2)
    assert seen == [1] and not observers
    with pytest.raises(ValueError, match='depth must be an integer >= 1'):
        ObserverThread(seen.append, depth=0)
