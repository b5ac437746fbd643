"""The recording window: sample topics cut to it, held topics (commands) in force over it."""

import random

import pytest

from maglev_ros.bags import BagError
from maglev_ros.bags.recording_window import Kept, RecordingWindow

P = 10  # ns between samples
FIELD, COMMAND = 'field', 'command'


def run(window, messages):
    """Offer ``(topic, log time, message, held)`` in order; return (topic, log time, msg) kept."""
    out = []
    for topic, log_time, message, held in messages:
        out += window.offer(topic, log_time, message, held)
    out += window.close()
    return [(k.topic, k.log_time, k.message) for k in out]


def bursts(n_samples, burst, answer_delay=0):
    """Samples every P ns; after each burst of ``burst`` samples one command answering
    its last sample (stamped with it), the real-time simulator's order."""
    messages = []
    for k in range(n_samples):
        messages.append((FIELD, k * P, f'f{k}', False))
        if (k + 1) % burst == 0:
            messages.append((COMMAND, k * P + answer_delay, f'c{k}', True))
    return messages


def test_samples_outside_are_dropped_and_an_open_window_keeps_everything():
    window = RecordingWindow()
    assert window.offer(FIELD, 5, 'a') == [Kept(FIELD, 5, 'a')]
    window.set(10, 20)
    assert window.offer(FIELD, 9, 'b') == [] and window.offer(FIELD, 21, 'c') == []
    assert window.offer(FIELD, 10, 'd') == [Kept(FIELD, 10, 'd')]
    assert window.offer(FIELD, 20, 'e') == [Kept(FIELD, 20, 'e')]
    assert window.newest_sample_ns == 20


def test_command_in_force_at_the_start_and_the_end_is_kept_there():
    # commands answer samples 4, 9, 14, ...; the window holds samples 12 .. 27
    kept = run(RecordingWindow(12 * P, 27 * P), bursts(40, 5))
    fields = [t for topic, t, _ in kept if topic == FIELD]
    assert fields == [k * P for k in range(12, 28)]
    commands = [(t, m) for topic, t, m in kept if topic == COMMAND]
    # c9 in force at sample 12 (kept at the start), then c14, c19, c24, and c24 once
    # more at the last sample (27): the converter holds it to the window's end
    assert commands == [(12 * P, 'c9'), (14 * P, 'c14'), (19 * P, 'c19'), (24 * P, 'c24'),
                        (27 * P, 'c24')]  # fmt: skip


def test_a_command_at_the_start_supersedes_the_one_before():
    kept = run(RecordingWindow(9 * P, 19 * P), bursts(30, 5))
    commands = [(t, m) for topic, t, m in kept if topic == COMMAND]
    assert commands == [(9 * P, 'c9'), (14 * P, 'c14'), (19 * P, 'c19')]  # ends on one


def test_a_window_between_two_commands_holds_the_one_before_throughout():
    kept = run(RecordingWindow(11 * P, 13 * P), bursts(30, 5))
    assert [(t, m) for topic, t, m in kept if topic == COMMAND] == [(11 * P, 'c9'), (13 * P, 'c9')]
    # with no end (a recording stopped by the user) the start rule alone, at close
    kept = run(RecordingWindow(11 * P), bursts(13, 5))
    assert [(t, m) for topic, t, m in kept if topic == COMMAND] == [(11 * P, 'c9')]


def test_no_rule_depends_on_the_order_across_topics():
    """A middleware keeps each topic's order, not the order across topics."""
    messages = bursts(60, 5, answer_delay=0)
    reference = sorted(run(RecordingWindow(12 * P, 47 * P), messages), key=lambda k: k[:2])
    rng = random.Random(3)
    for _ in range(20):
        queues = {FIELD: [m for m in messages if m[0] == FIELD],
                  COMMAND: [m for m in messages if m[0] == COMMAND]}  # fmt: skip
        shuffled = []
        while any(queues.values()):
            topic = rng.choice([t for t, q in queues.items() if q])
            shuffled.append(queues[topic].pop(0))
        # the end rule needs the newest sample of the window before a command after it
        shuffled_kept = run(RecordingWindow(12 * P, 47 * P), shuffled)
        assert sorted(shuffled_kept, key=lambda k: k[:2]) == reference


def test_a_window_set_later_takes_the_command_seen_before_it():
    """A lab starts with an empty window and sets it once the settling is over."""
    window = RecordingWindow(0, 1)
    messages = bursts(40, 5)
    kept = []
    for topic, log_time, message, held in messages:
        if log_time == 11 * P:  # set while the run goes on, after c9 was dropped
            window.set(12 * P, 30 * P)
        kept += window.offer(topic, log_time, message, held)
    kept += window.close()
    commands = [(k.log_time, k.message) for k in kept if k.topic == COMMAND]
    assert commands[0] == (12 * P, 'c9')
    assert commands[-1] == (30 * P, 'c29')


def test_nothing_held_is_written_without_a_sample_in_the_window():
    window = RecordingWindow(100, 200)
    assert window.offer(COMMAND, 50, 'c', held=True) == []
    assert window.close() == []


def test_bad_windows_are_refused():
    with pytest.raises(BagError, match='must end at or after its start 5 ns, got 4 ns'):
        RecordingWindow(5, 4)
    with pytest.raises(BagError, match='start at a log time >= 0 ns, got -1'):
        RecordingWindow().set(-1)
