"""The driver's topics feed the recorder and the bag converter unchanged.

A virtual V2x board (linear plant: the expected field of every record is known
from the PWM in force) on a pty, the real driver node, the excitation node
(timer trigger, antisymmetric pairs) and the recorder node run in this process
on one executor for about 1.5 s of board time; the bag is finalised and read
back with :func:`maglev_ros.bags.read_bag`, inputs being the currents the
driver reports as applied.
"""

from functools import partial

import numpy as np
import pytest
from rclpy.parameter import Parameter
from waiting import wait_for

from maglev_ros.bags import BagReader, load_bag_dataset, parse_channel, read_bag
from maglev_ros.bags.extraction import read_topics
from maglev_ros.hardware.firmware import LinearPlant, V2xFirmware
from maglev_ros.hardware.v2x_stream import RecordDecoder
from maglev_ros.hardware.virtual_board import VirtualBoard
from maglev_ros.nodes import contract
from maglev_ros.nodes.driver import DriverNode
from maglev_ros.nodes.excitation import ExcitationNode
from maglev_ros.nodes.recorder import RecorderNode

TIMEOUT = 20.0  # s, generous: the machine is shared
COUNTS_PER_AMPERE = 1000.0
AMPLITUDE = 0.25  # A: 250 counts, well inside +-4096
RECORD_S = 1.5  # board seconds to record
AXES = 'xyz'


@pytest.fixture(scope='module', autouse=True)
def compiled_kernels():
    """Initialise numba in this process before the nodes run.

    The decoder's kernels are numba functions: the first call in a process
    loads numba's compiler context (about 0.5 s, more on a busy machine). In
    the driver's I/O thread, mid-recording, that stall holds the GIL: the
    board's backlog then arrives as one burst, the publishers' history (1000
    samples) overflows and the bag loses messages. A driver started once per
    process pays this at start-up; here every test would.
    """
    firmware = V2xFirmware(LinearPlant.default(1), 1, startup_delay=0.0)
    batch = RecordDecoder(1).feed(firmware.advance_to(10_000))
    assert len(batch) > 0


def overrides(**values):
    return [Parameter(k, value=v) for k, v in values.items()]


def record(ctx, board, bag, read_interval=0.0):
    """Run driver, excitation and recorder until RECORD_S of samples are in the bag."""
    topics = [contract.field_topic(0), contract.CURRENTS_TOPIC, contract.COMMAND_TOPIC]
    nodes, spinner = [], None
    try:
        recorder = RecorderNode(
            context=ctx,
            parameter_overrides=overrides(
                path=str(bag), topics=topics, metadata_node='maglev_driver'
            ),
        )
        nodes.append(recorder)
        driver = DriverNode(
            context=ctx,
            parameter_overrides=overrides(
                port=board.path,
                n_sensors=1,
                counts_per_ampere=COUNTS_PER_AMPERE,
                start_enabled=True,
                command_timeout=1.0,
                read_interval=read_interval,
            ),
        )
        nodes.append(driver)
        excite = ExcitationNode(
            context=ctx,
            parameter_overrides=overrides(
                trigger='timer',
                sample_rate=1000.0,
                signal='prbs',
                amplitude=AMPLITUDE,
                pattern='pairs',
                length=1023,
                seed=5,
            ),
        )
        nodes.append(excite)
        spinner = contract.Spinner(ctx, nodes)
        wait_for(
            lambda: len(recorder.subscribed) == len(topics) and recorder.metadata_complete,
            what='the recorder to subscribe and store the driver parameters',
        )
        # the excitation reached the board: the applied PWM follows the pairs pattern
        wait_for(lambda: len(board.firmware.accepted) > 10, what='commands at the board')
        start = recorder.counts['/maglev/currents']
        wait_for(
            lambda: recorder.counts['/maglev/currents'] - start >= RECORD_S * 5000,
            what='samples in the bag',
        )
        recorder.close()  # finalised: index and metadata.yaml
        return dict(recorder.counts), dict(driver.counters), driver.decoder_stats
    finally:
        if spinner is not None:
            spinner.close()
        for node in reversed(nodes):
            node.destroy_node()


@pytest.mark.parametrize('read_interval', [0.0, 0.005])  # every burst; 5 bursts per read
def test_driver_bag_converts_to_the_board_fields_in_tesla(ctx, tmp_path, read_interval):
    plant = LinearPlant.default(1)
    board = VirtualBoard(partial(V2xFirmware, plant, 1, startup_delay=0.2))
    bag = tmp_path / 'bag'
    with board:
        counts, counters, stats = record(ctx, board, bag, read_interval)
        written = board.firmware.records_written
    assert (bag / 'metadata.yaml').is_file()
    assert counts['/maglev/currents'] >= RECORD_S * 5000
    assert counters['records'] <= written

    # the bag holds the driver's messages unchanged: every field equals what the board
    # sent (float32 mT) in tesla, for the PWM the twin currents message reports
    fields, currents = raw_samples(bag)
    assert fields.clock == currents.clock == 'header'
    assert np.all(np.diff(fields.stamps) > 0) and np.all(np.diff(currents.stamps) > 0)
    twins, fi, ci = np.intersect1d(fields.stamps, currents.stamps, return_indices=True)
    assert twins.size >= fields.stamps.size - 2  # the last sample may be cut by the close
    pwm = np.rint(currents.values[ci] * COUNTS_PER_AMPERE)
    np.testing.assert_array_equal(fields.values[fi], expected_tesla(plant, pwm))
    assert counters['resyncs'] == 0 and counters['dropped_bytes'] == 0  # link lost nothing

    outputs = [f'B{a}=maglev/sensor_0/field:magnetic_field.{a}' for a in AXES]
    inputs = [f'i{j}=maglev/currents:effort[{j}]' for j in range(4)]
    # the board's stamps are 200 us apart: the driver maps them with offset and drift and
    # slews offset corrections (at most 2 % of the spacing), it never steps
    spacing = np.diff(fields.stamps)
    assert np.median(spacing) == pytest.approx(200_000, abs=100)
    assert np.abs(spacing - 200_000).max() <= 0.02 * 200_000 + 100  # + drift, rounding
    dataset = read_bag(bag, outputs, inputs, Ts=200e-6)  # strict: a gap is an error
    data = dataset.data
    assert data.Ts == 200e-6
    assert data.N >= RECORD_S * 5000 - 10
    assert [r.clock for r in dataset.alignment.reports] == ['header', 'header']
    assert [r.duplicates for r in dataset.alignment.reports] == [0, 0]
    assert list(data.output_names) == ['Bx', 'By', 'Bz']
    assert list(data.input_names) == ['i0', 'i1', 'i2', 'i3']
    assert list(data.output_units) == ['T'] * 3 and list(data.input_units) == ['A'] * 4
    assert dataset.metadata['maglev_driver.port'] == board.path
    assert dataset.metadata['maglev_driver.counts_per_ampere'] == COUNTS_PER_AMPERE

    # nothing was lost between board and bag (all stamps are there, see above) and the
    # stamps never step: no gaps, the field and currents of a record share their stamp,
    # so both topics are taken sample by sample on the fields' own stamps
    methods = [r.method for r in dataset.alignment.reports]
    print(
        'converter report:',
        [g.describe() for g in dataset.gaps] or 'no gaps',
        methods,
        f'max spacing deviation {np.abs(spacing - 200_000).max()} ns',
    )
    assert dataset.gaps == ()
    assert methods == ['exact', 'exact'] and dataset.alignment.base == 'stamps'
    pwm = np.rint(np.asarray(data.u) * COUNTS_PER_AMPERE)  # every sample as the board sent it
    np.testing.assert_array_equal(np.asarray(data.y), expected_tesla(plant, pwm))
    # Ts estimated from the stamps: the same samples (the estimate includes the offset
    # corrections slewed during this short record: 0.1-0.2 % here, at most 2 %)
    estimated = read_bag(bag, outputs, inputs)
    assert estimated.data.Ts == pytest.approx(200e-6, rel=0.01)
    assert [r.method for r in estimated.alignment.reports] == ['exact', 'exact']
    np.testing.assert_array_equal(np.asarray(estimated.data.y), np.asarray(data.y))
    np.testing.assert_array_equal(np.asarray(estimated.data.u), np.asarray(data.u))

    # inputs: the applied currents follow the excitation (antisymmetric pairs, +-AMPLITUDE)
    u = np.asarray(data.u)
    np.testing.assert_array_equal(u[:, 1], -u[:, 0])
    np.testing.assert_array_equal(u[:, 3], -u[:, 2])
    excited = u[np.any(u != 0.0, axis=1)]
    assert excited.shape[0] > data.N // 2
    assert set(np.unique(np.abs(excited))) == {AMPLITUDE}
    for j in (0, 2):  # +-AMPLITUDE, and zero only before the first command reached the board
        assert set(np.unique(u[:, j])) in ({-AMPLITUDE, AMPLITUDE}, {-AMPLITUDE, 0.0, AMPLITUDE})
        idle = np.flatnonzero(u[:, j] == 0.0)
        np.testing.assert_array_equal(idle, np.arange(idle.size))  # a leading stretch

    # the command topic (no header: log times) converts too, next to the applied current
    commanded = load_bag_dataset(
        bag, outputs[:1], ['u=maglev/currents/command:effort[0]'], allow_gaps=True
    )  # a wall-clock timer: jitter, late ticks
    assert list(commanded.input_units) == ['A']
    assert set(np.unique(np.abs(np.asarray(commanded.u)))) == {AMPLITUDE}


def raw_samples(bag):
    """Header stamps and values of every field and currents message in the bag."""
    field_refs = [
        parse_channel(f'maglev/sensor_0/field:magnetic_field.{a}').terms[0][1] for a in AXES
    ]
    current_refs = [parse_channel(f'maglev/currents:effort[{j}]').terms[0][1] for j in range(4)]
    with BagReader(bag) as reader:
        samples = read_topics(
            reader, {'/maglev/sensor_0/field': field_refs, '/maglev/currents': current_refs}
        )
    return samples['/maglev/sensor_0/field'], samples['/maglev/currents']


def expected_tesla(plant, pwm):
    """Fields the V2x board sends for PWM counts (float32 mT), in tesla."""
    sent_mt = plant.offset_mT[0] + pwm @ plant.gain_mT_per_count[0].T
    return sent_mt.astype(np.float32).astype(np.float64) * 1e-3
