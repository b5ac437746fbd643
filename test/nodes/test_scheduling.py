"""The DDS event threads of a node process are moved to SCHED_BATCH; nothing else is."""

import os
import sys
from pathlib import Path

import pytest
import rclpy
from std_msgs.msg import Float64

from maglev_ros.nodes import contract
from maglev_ros.nodes.scheduling import EVENT_THREAD_PREFIX, relax_event_threads

pytestmark = pytest.mark.skipif(
    not (sys.platform.startswith('linux') and hasattr(os, 'SCHED_BATCH')),
    reason='SCHED_BATCH and /proc/self/task are Linux features',
)


def policies() -> dict[int, tuple[str, int]]:
    """tid -> (thread name, scheduling policy) of this process's threads."""
    out = {}
    for task in Path('/proc/self/task').iterdir():
        try:
            out[int(task.name)] = (
                (task / 'comm').read_text().strip(),
                os.sched_getscheduler(int(task.name)),
            )
        except OSError:  # the thread ended meanwhile
            continue
    return out


def test_event_threads_go_batch_and_nothing_else(ctx):
    node = rclpy.create_node('scheduling_test', context=ctx)
    try:
        node.create_publisher(Float64, 'scheduling_test', 10)  # the participant exists now
        before = policies()
        events = {tid for tid, (name, _) in before.items() if name.startswith(EVENT_THREAD_PREFIX)}
        names = sorted(name for name, _ in before.values())
        assert events, f'no {EVENT_THREAD_PREFIX}* thread among {names}'
        changed = relax_event_threads()
        after = policies()
        assert set(changed) == events
        for tid, (name, policy) in after.items():
            if tid in events:
                assert policy == os.SCHED_BATCH, name
            elif tid in before:
                assert policy == before[tid][1], name  # other threads untouched
        assert relax_event_threads() == changed  # idempotent
    finally:
        node.destroy_node()


def test_spinner_relaxes_the_event_threads(ctx):
    node = rclpy.create_node('scheduling_spinner_test', context=ctx)
    spinner = contract.Spinner(ctx, [node])
    try:
        events = [p for name, p in policies().values() if name.startswith(EVENT_THREAD_PREFIX)]
        assert events and all(p == os.SCHED_BATCH for p in events)
    finally:
        spinner.close()
        node.destroy_node()


def test_no_match_changes_nothing():
    before = policies()
    assert relax_event_threads(prefix='no-such-thread-name.') == []
    assert {tid: p for tid, (_, p) in policies().items() if tid in before} == {
        tid: p for tid, (_, p) in before.items() if tid in policies()
    }
