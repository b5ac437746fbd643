"""The recorder composed with a real-time simulator: taps, stamp log times, a window.

The set-up of ``maglev-lab --realtime``: the simulator steps bursts of 5
samples on the wall clock and hands each burst's messages to the taps of its
process; a command source answers each burst in the simulator's thread (as
the composed controller does) with one command that carries, as its value,
the stamp of the burst's last sample. The recorder (``intra_process``,
``log_clock: stamp``, ``record_from``, ``record_until``) must then hold
exactly the window's samples, each command logged at the sample it answers,
and the command in force at the window's start logged at its first sample
(and, if it was logged earlier, the one in force at its last sample logged
there too: the converter then holds it to the end), with no subscription of
its own on those topics.
"""

import struct

import numpy as np
import pytest
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray
from waiting import wait_for

from maglev_ros.bags import BagReader, read_bag
from maglev_ros.cdr.templates import float_array_prefix
from maglev_ros.nodes import intra_process
from maglev_ros.nodes.recorder import RecorderNode, RecorderParameterError, build_config
from maglev_ros.nodes.runtime import Spinner
from maglev_ros.nodes.simulator import SimulatorNode
from maglev_ros.topics import CLOCK_TOPIC, COMMAND_TOPIC, CURRENTS_TOPIC, field_topic

PERIOD_NS = 200_000  # 5 kHz
FIRST_S, LAST_S = 0.1, 0.3  # the recorded window: samples 500 .. 1500


def _params(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


class _BurstAnswerer:
    """Answers each simulated burst with one command, in the simulator's thread."""

    def __init__(self, ctx, sim, on_first=None) -> None:
        self.on_first = on_first  # called with the first burst (in the simulator's thread)
        self.tap = intra_process.tap(ctx, '/' + COMMAND_TOPIC)
        self.tap.add_publisher(Float64MultiArray)
        self.prefix = float_array_prefix(4)
        self.sent: list[int] = []
        self.source = sim.samples_source
        self.source.connect(self.on_batch, 'test_commands')

    def on_batch(self, batch) -> None:
        if self.on_first is not None:
            self.on_first, on_first = None, self.on_first
            on_first()
        last = int(batch.stamps_ns[-1])
        self.sent.append(last)
        self.tap.deliver([self.prefix + struct.pack('<4d', last * 1e-9, 0.0, 0.0, 0.0)])

    def close(self) -> None:
        self.source.disconnect(self.on_batch)
        self.tap.remove_publisher()


@pytest.mark.parametrize('at_run_time', [False, True], ids=['parameters', 'set-at-run-time'])
def test_composed_recorder_takes_the_taps_and_keeps_exactly_the_window(ctx, tmp_path, at_run_time):
    """With ``at_run_time`` the recorder starts with an empty window (1 ns at 0) and
    the window is set while the simulator runs, from its thread, as a board lab does."""
    sim = SimulatorNode(
        context=ctx,
        parameter_overrides=_params(
            mode='realtime', magnet='fixed', start_paused=True, marker_rate=0.0, sensors=[0]
        ),
    )
    window = dict(record_from=FIRST_S, record_until=LAST_S)
    recorder = None

    def set_window() -> None:
        result = recorder.set_parameters_atomically(_params(**window))
        assert result.successful, result.reason

    answerer = _BurstAnswerer(ctx, sim, set_window if at_run_time else None)
    topics = [field_topic(0), CURRENTS_TOPIC, COMMAND_TOPIC, CLOCK_TOPIC]
    recorder = RecorderNode(
        context=ctx,
        parameter_overrides=_params(
            path=str(tmp_path / 'bag'),
            topics=topics,
            log_clock='stamp',
            **(dict(record_from=0.0, record_until=1e-9) if at_run_time else window),
            intra_process=True,
            metadata_node='',
        ),
    )
    spinner = Spinner(ctx, [sim, recorder])
    try:
        wait_for(lambda: len(recorder.subscribed) == len(topics), what='the taps')
        assert not [s.topic_name for s in recorder.subscriptions]  # no middleware
        sim.set_paused(False)
        wait_for(lambda: sim.sim.samples > 1.2 * LAST_S * 5000, timeout=60.0, what='0.36 s')
        sim.set_paused(True)
    finally:
        spinner.close()
        answerer.close()
        recorder.destroy_node()
        sim.destroy_node()
    first, last = round(FIRST_S * 1e9), round(LAST_S * 1e9)
    n = (last - first) // PERIOD_NS + 1
    with BagReader(tmp_path / 'bag') as reader:
        logged = {}
        for topic, stamp, _ in reader.messages(topics):
            logged.setdefault(topic, []).append(stamp)
    fields = np.array(logged['/' + field_topic(0)])
    np.testing.assert_array_equal(fields, first + PERIOD_NS * np.arange(n))  # the window
    assert len(logged['/' + CURRENTS_TOPIC]) == n
    commands = np.array(logged['/' + COMMAND_TOPIC])
    # the command in force at the start (answering the burst before it, unless a burst
    # ends at the first sample), then each command at the last sample of the burst it
    # answers, up to the window's end
    answered = np.array([s for s in answerer.sent if first <= s <= last])
    expected = answered if answered[0] == first else np.r_[first, answered]
    if expected[-1] < last:  # the one in force at the window's last sample, logged there
        expected = np.r_[expected, last]
    np.testing.assert_array_equal(commands, expected)
    data = read_bag(  # bursts of uneven length (a loaded machine): commands at uneven times
        tmp_path / 'bag',
        [f'b={field_topic(0)}:magnetic_field.x'],
        [f'c={COMMAND_TOPIC}:data[0]'],
        allow_gaps=True,
    ).data
    assert data.N == n  # every sample has its input: nothing trimmed
    u = np.asarray(data.u)[:, 0]
    stamps = first + PERIOD_NS * np.arange(n)
    held = np.array([max([s for s in answerer.sent if s <= t], default=-1) for t in stamps])
    np.testing.assert_allclose(u, held * 1e-9, rtol=0, atol=1e-12)  # u(t): answer to <= t


def test_a_window_set_at_run_time_is_checked_and_keeps_the_bag(ctx, tmp_path):
    recorder = RecorderNode(
        context=ctx,
        parameter_overrides=_params(
            path=str(tmp_path / 'bag'), record_until=3.0, metadata_node=''
        ),
    )
    try:  # the bag exists now: a change of the window does not check its path again
        result = recorder.set_parameters_atomically(_params(record_from=4.0))
        assert not result.successful and 'record_until must be 0' in result.reason
        assert (recorder.config.record_from, recorder.config.record_until) == (0.0, 3.0)
        assert recorder.set_parameters_atomically(_params(record_from=4.0, record_until=5.0))
        assert (recorder.config.record_from, recorder.config.record_until) == (4.0, 5.0)
        assert recorder.config.path == str(tmp_path / 'bag')
        assert not recorder.set_parameters_atomically(_params(path='elsewhere')).successful
    finally:
        recorder.destroy_node()


def test_window_and_log_clock_are_checked(tmp_path):
    path = str(tmp_path / 'bag')
    with np.testing.assert_raises_regex(RecorderParameterError, 'record_until must be 0'):
        build_config({'path': path, 'record_from': 2.0, 'record_until': 1.0})
    cfg = build_config({'path': path, 'log_clock': 'stamp', 'record_until': 1.0})
    assert cfg.log_clock == 'stamp' and cfg.record_until == 1.0 and not cfg.intra_process
