"""fifo_priority: SCHED_FIFO for a block where allowed, the reason where not."""

from __future__ import annotations

import os

import pytest

from maglev_ros.realtime_priority import fifo_priority


def test_priority_zero_leaves_the_scheduling_alone():
    before = os.sched_getscheduler(0)
    with fifo_priority(0) as note:
        assert note == '' and os.sched_getscheduler(0) == before


def test_a_priority_is_applied_for_the_block_or_the_refusal_is_said():
    before = os.sched_getscheduler(0), os.sched_getparam(0).sched_priority
    with fifo_priority(10) as note:
        if note:  # no right to real-time scheduling here (not root, no rtprio limit)
            assert 'SCHED_FIFO at priority 10 refused' in note and 'rtprio' in note
            assert os.sched_getscheduler(0) == before[0]
        else:
            assert os.sched_getscheduler(0) == os.SCHED_FIFO
            assert os.sched_getparam(0).sched_priority == 10
    assert (os.sched_getscheduler(0), os.sched_getparam(0).sched_priority) == before


@pytest.mark.parametrize('priority', [-1, 100])
def test_a_priority_out_of_range_is_refused(priority):
    with pytest.raises(ValueError, match='real-time priority must be 0 \\(none\\) to 99'):
        with fifo_priority(priority):
            pass
