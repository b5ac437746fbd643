import numpy as np
import pytest

from maglev_ros.bags import BagError, read_bag
from maglev_ros.bags.alignment import Source, align

from .recordings import (
    COMMAND,
    CURRENTS,
    METADATA,
    SENSOR,
    TS,
    lockstep_data,
    write_lockstep_bag,
)

OUTPUTS = ['maglev/sensor_0/field:magnetic_field.x', 'maglev/sensor_0/field:magnetic_field.z']
INPUTS = [
    'maglev/currents:effort[0]',
    'ux=0.5*maglev/currents:effort[0]-0.5*maglev/currents:effort[1]',
]


@pytest.fixture(scope='module')
def run():
    return lockstep_data(1000)


@pytest.fixture(scope='module', params=['mcap', 'sqlite3'])
def lockstep_bag(request, tmp_path_factory, run):
    return write_lockstep_bag(tmp_path_factory.mktemp(request.param) / 'run', run, request.param)


def test_lockstep_run_gives_back_the_exact_sequence(lockstep_bag, run):
    ds = read_bag(lockstep_bag, OUTPUTS, INPUTS + ['/maglev/currents/command:data[3]'])
    data = ds.data
    assert data.N == 1000 and data.Ts == TS
    np.testing.assert_array_equal(data.y, run.field[:, [0, 2]])
    np.testing.assert_array_equal(data.u[:, 0], run.currents[:, 0])
    np.testing.assert_array_equal(
        data.u[:, 1], 0.5 * run.currents[:, 0] - 0.5 * run.currents[:, 1]
    )
    np.testing.assert_array_equal(data.u[:, 2], run.command[:, 3])
    assert data.input_names[1] == 'ux'
    assert data.output_units == ('T', 'T') and data.input_units == ('A', 'A', 'A')
    assert ds.t0_ns == run.stamps[0]
    assert [(r.topic, r.clock, r.method) for r in ds.alignment.reports] == [
        (SENSOR, 'header', 'exact'),
        (CURRENTS, 'header', 'exact'),
        (COMMAND, 'log', 'exact'),
    ]
    assert ds.gaps == () and ds.alignment.trimmed == (0, 0)
    assert ds.alignment.base == 'stamps'  # uniform: the sensor's own stamps, on the grid
    assert ds.metadata == METADATA
    est, val = ds.split(0.5)
    assert est.N == val.N == 500
    summary = ds.summary()
    assert summary['samples'] == 1000 and summary['gaps'] == []
    assert summary['estimation']['samples'] == 500


def test_commands_without_header_are_held_by_log_time(tmp_path, run):
    # commands logged 0.3 Ts after the samples: each sample takes the last command before it
    bag = write_lockstep_bag(tmp_path / 'late', run, command_delay_ns=60_000)
    ds = read_bag(bag, OUTPUTS[:1], ['maglev/currents/command:data[0]'])
    report = ds.alignment.reports[1]
    assert (report.clock, report.method) == ('log', 'zoh')
    assert ds.alignment.trimmed == (1, 0)  # no command yet at the first sample
    np.testing.assert_array_equal(ds.data.u[:, 0], run.command[:-1, 0])
    np.testing.assert_array_equal(ds.data.y[:, 0], run.field[1:, 0])


def test_zoh_of_slower_inputs():
    stamps = np.arange(100, dtype=np.int64) * 1_000_000
    y = Source('/y', stamps, np.arange(100.0), 'output')
    u = Source('/u', stamps[::10] + 500_000, np.arange(10.0) * 10, 'input', 'log')
    al = align([y, u])
    assert al.Ts == pytest.approx(1e-3)
    assert al.trimmed == (1, 0)
    expected = np.repeat(np.arange(10.0) * 10, 10)[:99]
    np.testing.assert_array_equal(al.values[1][:, 0], expected)
    assert al.reports[1].method == 'zoh' and al.reports[1].gaps == ()


def test_gaps_are_refused_then_filled(tmp_path, run):
    bag = write_lockstep_bag(
        tmp_path / 'gaps', run, drop={SENSOR: [300, 301, 302], COMMAND: [700]}
    )
    specs = (OUTPUTS[:1], ['maglev/currents/command:data[0]'])
    with pytest.raises(
        BagError,
        match=r"gap in topic '/maglev/sensor_0/field': 3 missing "
        r'samples after t = 0\.059800 s \(2 gaps, 4 samples in all\); '
        r'pass allow_gaps=True',
    ):
        read_bag(bag, *specs)
    ds = read_bag(bag, *specs, allow_gaps=True)
    assert [g.describe() for g in ds.gaps] == [
        '/maglev/sensor_0/field: 3 missing samples after t = 0.059800 s, filled by linear',
        '/maglev/currents/command: 1 missing sample after t = 0.139800 s, filled by zoh',
    ]
    y, u = ds.data.y[:, 0], ds.data.u[:, 0]
    assert ds.data.N == 1000
    keep = np.setdiff1d(np.arange(1000), [300, 301, 302])
    np.testing.assert_array_equal(y[keep], run.field[keep, 0])
    np.testing.assert_allclose(
        y[300:303], np.interp([300, 301, 302], [299, 303], run.field[[299, 303], 0]), rtol=1e-12
    )
    assert u[700] == run.command[699, 0]  # held
    assert ds.alignment.reports[0].method == 'exact'


def test_jittery_outputs_are_resampled_linearly():
    rng = np.random.default_rng(0)
    stamps = np.arange(200, dtype=np.int64) * 1_000_000
    jitter = stamps + rng.integers(-200_000, 200_000, 200)
    jitter[0] = 0
    other = Source('/y2', jitter, np.sin(jitter * 1e-9)[:, None], 'output')
    al = align([Source('/y', stamps, np.zeros(200), 'output'), other])
    assert [r.method for r in al.reports] == ['exact', 'linear']
    np.testing.assert_allclose(al.values[1][:, 0], np.sin(stamps[: al.N] * 1e-9), atol=1e-6)


def test_duplicates_are_dropped_and_counted():
    stamps = np.array([0, 1, 1, 2, 3], dtype=np.int64) * 1_000_000
    al = align([Source('/y', stamps, np.array([0.0, 1.0, 9.0, 2.0, 3.0]), 'output')])
    np.testing.assert_array_equal(al.values[0][:, 0], [0.0, 1.0, 2.0, 3.0])
    assert al.reports[0].duplicates == 1


def test_period_estimate_does_not_drift_at_3khz():
    stamps = np.rint(np.arange(30000) * 1e9 / 3000).astype(np.int64)
    al = align([Source('/y', stamps, np.arange(30000.0), 'output')])
    assert al.Ts == pytest.approx(1 / 3000, rel=1e-9)
    assert al.reports[0].method == 'exact' and al.N == 30000
    assert al.base == 'stamps' and al.t0_ns == 0


def test_unknown_topic_field_and_bad_specs(lockstep_bag):
    with pytest.raises(
        BagError,
        match=r"no topic '/maglev/sensor_3/field'; its topics: "
        r'/maglev/currents \(sensor_msgs/msg/JointState\)',
    ):
        read_bag(lockstep_bag, ['maglev/sensor_3/field:magnetic_field.x'])
    with pytest.raises(
        BagError,
        match=r'sensor_msgs/msg/MagneticField has no field '
        r"'magnetic_fild'; its fields: header, magnetic_field, "
        r'magnetic_field_covariance',
    ):
        read_bag(lockstep_bag, ['maglev/sensor_0/field:magnetic_fild.x'])
    with pytest.raises(
        BagError,
        match=r'magnetic_field \(geometry_msgs/msg/Vector3\) has no '
        r"field 'w'; its fields: x, y, z",
    ):
        read_bag(lockstep_bag, ['maglev/sensor_0/field:magnetic_field.w'])
    with pytest.raises(
        BagError,
        match=r'is a geometry_msgs/msg/Vector3 message, not a '
        r'number; choose one of its fields: x, y, z',
    ):
        read_bag(lockstep_bag, ['maglev/sensor_0/field:magnetic_field'])
    with pytest.raises(
        BagError,
        match=r'effort\[4\]: index 4 out of range, the messages '
        r'have 4 elements',
    ):
        read_bag(lockstep_bag, OUTPUTS, ['maglev/currents:effort[4]'])
    with pytest.raises(BagError, match=r'currents:name\[0\] is a string, not a number'):
        read_bag(lockstep_bag, OUTPUTS, ['maglev/currents:name[0]'])
    with pytest.raises(BagError, match='invalid channel spec'):
        read_bag(lockstep_bag, ['maglev/sensor_0/field'])
    with pytest.raises(BagError, match='at least one output'):
        read_bag(lockstep_bag, [])


def test_slower_output_on_grid_points_is_reported_as_interpolated():
    base = np.arange(50, dtype=np.int64) * 200_000
    slow = base[::5]
    al = align(
        [
            Source('/fast', base, np.zeros(50), 'output'),
            Source('/slow', slow, np.arange(10.0), 'output'),
        ]
    )
    assert [r.method for r in al.reports] == ['exact', 'linear']
    np.testing.assert_allclose(al.values[1][:46, 0], np.arange(46) / 5.0)
    assert al.trimmed == (0, 4)  # the slow topic ends at sample 45


def test_an_input_sent_once_is_held_to_the_end():
    stamps = np.arange(20, dtype=np.int64) * 1_000_000
    al = align(
        [
            Source('/y', stamps, np.zeros(20), 'output'),
            Source('/setpoint', np.array([4_500_000]), np.array([0.7]), 'input', 'log'),
        ]
    )
    assert al.trimmed == (5, 0)
    np.testing.assert_array_equal(al.values[1][:, 0], np.full(15, 0.7))


def test_topics_on_different_clocks_do_not_overlap():
    sim = np.arange(10, dtype=np.int64) * 1_000_000  # simulated time from 0
    wall = 1_700_000_000_000_000_000 + sim  # a recorder stamping with the wall clock
    with pytest.raises(
        BagError,
        match=r'do not overlap in time: /y 0\.000\.\.0\.009 s, '
        r'/u .*different clocks',
    ):
        align(
            [
                Source('/y', sim, np.zeros(10), 'output'),
                Source('/u', wall, np.zeros(10), 'input', 'log'),
            ]
        )
