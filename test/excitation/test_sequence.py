"""The excitation's command sequence, without ROS: periods, offset, limit, stamped messages."""

import numpy as np
import pytest

from maglev_ros.cdr import currents_layout
from maglev_ros.cdr.batch import RawMessageBatch
from maglev_ros.cdr.typestore import jazzy_typestore
from maglev_ros.excitation import CommandSequence

PERIOD = np.arange(12.0).reshape(3, 4) / 10
OFFSET = [0.0, 0.0, 0.05, 0.05]


def _decode(message):
    msg = jazzy_typestore().deserialize_cdr(message, 'sensor_msgs/msg/JointState')
    return msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, list(msg.name), msg.effort


def test_periods_then_the_offset_then_nothing():
    seq = CommandSequence(PERIOD, cycles=2, offset=OFFSET, max_commands=8)
    got = [seq.next() for _ in range(9)]
    np.testing.assert_array_equal(got[:6], np.vstack([PERIOD, PERIOD]))
    assert seq.sent == 8 and seq.finished and seq.exhausted
    np.testing.assert_array_equal(got[6:8], [OFFSET, OFFSET])
    assert got[8] is None


def test_forever_without_cycles_or_limit():
    seq = CommandSequence(PERIOD, cycles=0, offset=OFFSET)
    got = [seq.next() for _ in range(10)]
    np.testing.assert_array_equal(got, PERIOD[np.arange(10) % 3])
    assert not seq.finished and not seq.exhausted


def test_messages_are_stamped_commands_of_the_contract():
    seq = CommandSequence(PERIOD, cycles=1, offset=OFFSET, max_commands=2)
    stamp, names, effort = _decode(seq.message(1_234_567_890_123))
    assert (stamp, names) == (1_234_567_890_123, ['x+', 'x-', 'y+', 'y-'])
    np.testing.assert_array_equal(effort, PERIOD[0])
    sample = RawMessageBatch(currents_layout()).serialise(np.array([600_000]), np.ones((1, 4)))
    stamp, _, effort = _decode(seq.answer(sample[0]))  # stamped with the sample it answers
    assert stamp == 600_000
    np.testing.assert_array_equal(effort, PERIOD[1])
    assert seq.answer(sample[0]) is None and seq.message(0) is None  # max_commands sent


def test_an_unreadable_sample_is_not_answered():
    seq = CommandSequence(PERIOD, cycles=0, offset=OFFSET)
    assert seq.answer(b'\x00\x01\x00\x00garbage') is None and seq.sent == 0


def test_a_period_must_be_rows_of_four_currents():
    with pytest.raises(ValueError, match=r'commands must have shape \(length, 4\), got \(3,\)'):
        CommandSequence(np.zeros(3), cycles=0, offset=OFFSET)
