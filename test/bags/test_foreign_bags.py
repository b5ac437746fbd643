"""Bags not written by BagWriter: compressed, custom message types, unfilled headers."""

import numpy as np
import pytest
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from maglev_ros.bags import BagReader, read_bag

from .recordings import currents_msg, field_msg

SAMPLE = 'maglev_msgs/msg/Sample'
SAMPLE_DEF = 'std_msgs/Header header\nfloat64[4] current\nstring note\nfloat32 level\n'


def _store():
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(SAMPLE_DEF, SAMPLE))
    return store


@pytest.mark.parametrize(
    ('storage', 'mode'),
    [
        (StoragePlugin.MCAP, CompressionMode.STORAGE),
        (StoragePlugin.SQLITE3, CompressionMode.MESSAGE),
        (StoragePlugin.MCAP, CompressionMode.FILE),
    ],
)
def test_compressed_bag_with_a_custom_type(tmp_path, storage, mode):
    store = _store()
    Sample, Header = store.types[SAMPLE], store.types['std_msgs/msg/Header']
    Time = store.types['builtin_interfaces/msg/Time']
    n = 50
    writer = Writer(tmp_path / 'rec', version=8, storage_plugin=storage)
    writer.set_compression(mode, CompressionFormat.ZSTD)
    with writer:
        conn = writer.add_connection('/maglev/sample', SAMPLE, typestore=store)
        for k in range(n):
            note = 'x' * (k % 3)  # the layout changes from message to message
            msg = Sample(
                header=Header(stamp=Time(sec=5, nanosec=1_000_000 * k), frame_id=''),
                current=np.array([k, -k, 0.5 * k, 1.0]),
                note=note,
                level=np.float32(0.25 * k),
            )
            writer.write(conn, 10**9 * k, bytes(store.serialize_cdr(msg, SAMPLE)))
    ds = read_bag(
        tmp_path / 'rec',
        ['maglev/sample:level'],
        ['u=maglev/sample:current[0]-maglev/sample:current[1]'],
    )
    np.testing.assert_array_equal(ds.data.y[:, 0], 0.25 * np.arange(n))
    np.testing.assert_array_equal(ds.data.u[:, 0], 2.0 * np.arange(n))
    assert ds.data.Ts == pytest.approx(1e-3)  # header stamps, not the 1 s log times
    assert ds.alignment.reports[0].clock == 'header'


def test_unfilled_headers_fall_back_to_log_time(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    with Writer(tmp_path / 'zero', version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(
            '/maglev/currents', 'sensor_msgs/msg/JointState', typestore=store
        )
        for k in range(20):
            writer.write(conn, 1000 + 2_000_000 * k, currents_msg(0, [k, 0.0, 0.0, 0.0]))
    ds = read_bag(tmp_path / 'zero', ['maglev/currents:effort[0]'])
    assert ds.alignment.reports[0].clock == 'log'
    assert ds.data.Ts == pytest.approx(2e-3)
    np.testing.assert_array_equal(ds.data.y[:, 0], np.arange(20.0))


def test_a_single_storage_file_opens_too(tmp_path):
    store = get_typestore(Stores.ROS2_JAZZY)
    with Writer(tmp_path / 'one', version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection(
            '/maglev/sensor_0/field', 'sensor_msgs/msg/MagneticField', typestore=store
        )
        for k in range(5):
            writer.write(conn, k, field_msg(k, [k, 0.0, 0.0]))
    with BagReader(tmp_path / 'one' / 'one.mcap') as reader:
        assert reader.storage == 'mcap'
        assert reader.topic('maglev/sensor_0/field').count == 5
