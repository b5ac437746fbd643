"""SampleAssembler: the same released samples whatever order the parts are handled in."""

import itertools
import random

import pytest

from maglev_ros.loop.sample_assembly import SampleAssembler

WAIT = 10


def _feed(messages, n_parts=4, wait=WAIT):
    a = SampleAssembler(n_parts, wait)
    out = []
    for part, stamp, value in messages:
        out.extend(a.add(part, stamp, value))
    return a, [(s.stamp, s.parts) for s in out]


def _sample(stamp, n_parts=4):
    return [(p, stamp, f'{p}@{stamp}') for p in range(n_parts)]


def test_a_sample_is_released_once_complete_in_any_order():
    parts = _sample(5)
    for order in itertools.permutations(parts):
        a, out = _feed(order)
        assert out == [(5, ('0@5', '1@5', '2@5', '3@5'))]
        assert a.pending == 0 and a.late == 0


def test_interleaved_samples_give_the_same_release_in_any_per_topic_order():
    # each topic delivers in order; topics interleave arbitrarily
    rng = random.Random(3)
    stamps = [10, 11, 12, 13, 14]
    queues = [[(p, s, f'{p}@{s}') for s in stamps] for p in range(4)]
    expected = [(s, tuple(f'{p}@{s}' for p in range(4))) for s in stamps]
    for _ in range(200):
        qs = [list(q) for q in queues]
        order = []
        while any(qs):
            q = rng.choice([q for q in qs if q])
            order.append(q.pop(0))
        _, out = _feed(order, wait=100)
        assert out == expected


def test_a_part_is_missing_only_once_a_later_message_of_its_topic_arrived():
    # sensor 1's message of stamp 1 is lost: stamp 1 waits until sensor 1's stamp 2 arrives
    msgs = [m for m in _sample(1) if m[0] != 1]
    a, out = _feed(msgs)
    assert out == [] and a.pending == 1
    out = a.add(1, 2, 'x')
    assert [(s.stamp, s.parts, s.complete) for s in out] == [
        (1, ('0@1', None, '2@1', '3@1'), False)
    ]
    assert a.pending == 1  # stamp 2 waits for its other parts


def test_a_later_complete_sample_releases_the_earlier_ones_first():
    msgs = [(0, 1, 'a')] + _sample(2)
    _, out = _feed(msgs)
    assert [s for s, _ in out] == [1, 2]
    assert out[0][1] == ('a', None, None, None)


def test_a_silent_topic_waits_wait_ns_of_stamps():
    # part 3 never publishes: a sample is released once stamps more than WAIT later arrive
    a = SampleAssembler(4, WAIT)
    released = []
    for stamp in range(0, 30, 2):
        for p in range(3):
            released += [(stamp, s.stamp) for s in a.add(p, stamp, p)]
    assert released and all(now - s > WAIT for now, s in released)
    assert [s for _, s in released] == sorted(s for _, s in released)


def test_late_parts_are_dropped_and_counted():
    a, out = _feed(_sample(3) + _sample(4))
    assert [s for s, _ in out] == [3, 4]
    assert a.add(2, 3, 'late') == [] and a.late == 1


@pytest.mark.parametrize('n_parts, wait', [(0, 1), (2, -1)])
def test_bad_arguments_are_refused(n_parts, wait):
    with pytest.raises(ValueError):
        SampleAssembler(n_parts, wait)
