"""Channels on live messages: ChannelSampler and ChannelIdentifier."""

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.signal import lfilter

from maglev_ros.bags import BagError, BagReader, load_bag_dataset
from maglev_ros.bags.live import ChannelIdentifier, ChannelSampler, StampAligner
from maglev_ros.sysid import arx

from .recordings import COMMAND, CURRENTS, SENSOR, lockstep_data, write_lockstep_bag

UX = f'ux=0.5*{COMMAND}:data[0]-0.5*{COMMAND}:data[1]'
BX = f'Bx={SENSOR}:magnetic_field.x'


def field(x, y=0.0, z=0.0):
    return SimpleNamespace(magnetic_field=SimpleNamespace(x=x, y=y, z=z))


def command(*values):
    return SimpleNamespace(data=list(values))


def test_sampler_pairs_outputs_with_the_trigger_and_counts():
    sampler = ChannelSampler([BX, f'{SENSOR}:magnetic_field.z'], [UX])
    assert sampler.trigger == COMMAND and sampler.topics == (SENSOR, COMMAND)
    assert sampler.names == (('Bx', f'{SENSOR}:magnetic_field.z'), ('ux',))
    assert sampler.add(COMMAND, command(1.0, -1.0)) is None  # no field yet: waiting
    assert sampler.add('maglev/sensor_0/field', field(2e-3, z=5e-2)) is None  # not the trigger
    y, u = sampler.add(COMMAND, command(0.4, -0.2))
    np.testing.assert_allclose(y, [2e-3, 5e-2])
    np.testing.assert_allclose(u, [0.3])
    sampler.add(COMMAND, command(1.0, 1.0))  # field held from before
    assert sampler.add(COMMAND, SimpleNamespace(data=[1.0])) is None  # no data[1]
    assert sampler.add(COMMAND, command(float('nan'), 0.0)) is None
    assert sampler.add('/other', field(1.0)) is None
    counts = sampler.counts
    assert (counts.samples, counts.waiting, counts.held, counts.bad) == (2, 1, 1, 2)
    sampler.reset()
    assert sampler.counts.samples == 0 and sampler.add(COMMAND, command(0, 0)) is None


@pytest.mark.parametrize(
    ('args', 'match'),
    [
        (([], [UX]), 'at least one output'),
        (([BX], [UX], 'maglev/currents'), "trigger topic '/maglev/currents' is not read"),
        (([f'{SENSOR}:magnetic_field.x+'], []), 'invalid channel spec'),
        ((BX, [UX]), 'lists of channel specs'),
    ],
)
def test_sampler_bad_setup(args, match):
    with pytest.raises(BagError, match=match):
        ChannelSampler(*args)


def test_identifier_on_a_replayed_bag_equals_batch_arx_of_the_converted_bag(tmp_path):
    """Messages in lockstep order (field, currents, command) give the converter's samples."""
    run = lockstep_data(5000, seed=11)
    ux = 0.5 * run.command[:, 0] - 0.5 * run.command[:, 1]
    field_x = lfilter([0.0, 2e-3, 1e-3], [1.0, -1.2, 0.5], ux)
    field_x += 1e-5 * np.random.default_rng(2).standard_normal(run.stamps.size)
    values = run.field.copy()
    values[:, 0] = field_x
    # lockstep: the recorder logs the command at its sample's (simulated) time
    bag = write_lockstep_bag(tmp_path / 'run', replace(run, field=values), command_delay_ns=0)
    data = load_bag_dataset(bag, [BX], [UX])
    assert data.N == 5000
    # fields in tesla: P0 = 1e4 I (MATLAB's default, for unit-scale signals) is a strong
    # prior here (y'y ~ 5e-3 per coefficient); 1e10 makes it negligible
    identifier = ChannelIdentifier([BX], [UX], 2, 2, 1, initial_covariance=1e10)
    with BagReader(bag) as reader:
        decoded = {}
        for topic in (SENSOR, CURRENTS, COMMAND):
            decode = reader.deserializer(topic)
            decoded[topic] = [decode(raw) for _, _, raw in reader.messages([topic])]
    for k in range(data.N):  # arrival order of a lockstep sample: readings, then the command
        for topic in (SENSOR, CURRENTS, COMMAND):
            identifier.add(topic, decoded[topic][k])
    assert identifier.sampler.counts.samples == data.N
    np.testing.assert_array_equal(identifier.arx._fit_y[:, 0], data.y[-1000:, 0])
    batch = arx(data, 2, 2, 1).theta
    assert np.max(np.abs(identifier.arx.theta - batch)) < 1e-6 * np.max(np.abs(batch))
    layout = identifier.layout()
    assert layout.labels == ('theta', 'A[Bx,Bx] na=2', 'B[Bx,ux] nb=2 nk=1')
    np.testing.assert_allclose(layout.block('B[Bx,ux]'), [2e-3, 1e-3], rtol=1e-2)
    assert identifier.model(2e-4).input_names == ('ux',)
    status = identifier.status()
    assert status.samples == data.N and status.fit[0] > 90
    identifier.reset()
    assert identifier.status().samples == 0


def test_identifier_needs_an_input():
    with pytest.raises(BagError, match='at least one input'):
        ChannelIdentifier([BX], [], 2, 2, 1)


def test_stamp_aligner_completes_a_sample_whatever_the_arrival_order():
    topics = ('/f0', '/f1', '/cur', '/cmd')
    aligner = StampAligner(topics, {'/f0', '/f1', '/cur'}, trigger='/cur')
    assert aligner.add('/cur', 10, 'c10') == []  # trigger first: waits for the fields
    assert aligner.add('/f1', 10, 'b10') == []
    assert aligner.add('/cmd', None, 'u') == [('/cmd', 'u')]  # unstamped: at once
    assert aligner.add('/f0', 10, 'a10') == [('/f0', 'a10'), ('/f1', 'b10'), ('/cur', 'c10')]
    # stamp 20 never completes; 30 does: 20 is dropped, and a late 20 too
    assert aligner.add('/f0', 20, 'a20') == []
    for topic in ('/cur', '/f0', '/f1'):
        out = aligner.add(topic, 30, topic + '30')
    assert [t for t, _ in out] == ['/f0', '/f1', '/cur'] and aligner.dropped == 1
    assert aligner.add('/f1', 20, 'late') == [] and aligner.dropped == 2
    aligner.reset()
    assert aligner.dropped == 0 and aligner.add('/f0', 5, 'a5') == []


def test_stamp_aligner_keeps_at_most_depth_incomplete_stamps():
    aligner = StampAligner(('/a', '/b'), {'/a', '/b'}, trigger='/b', depth=3)
    for k in range(5):
        assert aligner.add('/a', k, k) == []
    assert aligner.dropped == 2  # stamps 0 and 1 pushed out
    assert aligner.add('/b', 4, 'b4') == [('/a', 4), ('/b', 'b4')]
    assert aligner.dropped == 4  # 2 and 3 were older than the completed 4


def _burst_run(complete_on_next):
    """Fields of stamps 1..5, then the command c1, then fields of 6..10; samples (y, u)."""
    sampler = ChannelSampler([BX], [UX], trigger=SENSOR)
    aligner = StampAligner((SENSOR, COMMAND), {SENSOR}, SENSOR, complete_on_next=complete_on_next)
    arrivals = [(COMMAND, None, command(0.0, 0.0))]  # c0: the command before the run
    arrivals += [(SENSOR, k, field(float(k))) for k in range(1, 6)]
    arrivals += [(COMMAND, None, command(1.0, -1.0))]  # c1 answers samples 1..5
    arrivals += [(SENSOR, k, field(float(k))) for k in range(6, 11)]
    samples = []
    for topic, stamp, message in arrivals:
        for name, released in aligner.add(topic, stamp, message):
            sample = sampler.add(name, released)
            if sample is not None:
                samples.append((sample[0][0], sample[1][0]))
    return samples


def test_stamp_aligner_complete_on_next_pairs_a_burst_with_the_command_after_it():
    # sample 5 is followed by c1 (ux = 1): its input; samples 1-4 keep c0 (ux = 0)
    assert _burst_run(True) == [
        (1, 0),
        (2, 0),
        (3, 0),
        (4, 0),
        (5, 1),
        (6, 1),
        (7, 1),
        (8, 1),
        (9, 1),
    ]
    # without it a sample goes at once: all of 1..5 with c0, the last (10) not held back
    assert _burst_run(False) == [(k, 0.0 if k <= 5 else 1.0) for k in range(1, 11)]


def test_stamp_aligner_complete_on_next_holds_until_a_newer_stamp():
    aligner = StampAligner(('/f0', '/cur', '/cmd'), {'/f0', '/cur'}, '/cur', complete_on_next=True)
    assert aligner.add('/f0', 10, 'a10') == []
    assert aligner.add('/cur', 10, 'c10') == []  # complete, held
    assert aligner.add('/cmd', None, 'u') == [('/cmd', 'u')]
    assert aligner.add('/cur', 10, 'late') == [] and aligner.dropped == 1  # not a newer stamp
    # the first message of stamp 20 releases 10's set; 20 is incomplete: nothing more
    assert aligner.add('/cur', 20, 'c20') == [('/f0', 'a10'), ('/cur', 'c10')]
    assert aligner.add('/f0', 20, 'a20') == []  # 20 complete: held in turn
    aligner.reset()  # forgets the held set
    assert aligner.add('/f0', 30, 'a30') == [] and aligner.add('/cur', 30, 'c30') == []
    assert aligner.add('/f0', 40, 'a40') == [('/f0', 'a30'), ('/cur', 'c30')]
