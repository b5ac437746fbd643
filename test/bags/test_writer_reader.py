import numpy as np
import pytest

from maglev_ros.bags import BagError, BagReader, BagWriter
from maglev_ros.bags.typestore import cdr_deserializer, jazzy_typestore

from .recordings import (
    COMMAND,
    CURRENTS,
    METADATA,
    SENSOR,
    currents_msg,
    field_msg,
    lockstep_data,
    write_lockstep_bag,
)

STORAGES = ['mcap', 'sqlite3']


@pytest.mark.parametrize('storage', STORAGES)
def test_every_message_and_stamp_reads_back(tmp_path, storage):
    run = lockstep_data(200)
    written: dict[str, list] = {}
    bag = write_lockstep_bag(tmp_path / 'run', run, storage, log=written)
    assert sorted(written) == sorted([COMMAND, CURRENTS, SENSOR])
    assert [s for s, _ in written[COMMAND]] == list(run.stamps)
    with BagReader(bag) as reader:
        assert reader.storage == storage
        assert {t: i.msgtype for t, i in reader.topics.items()} == {
            SENSOR: 'sensor_msgs/msg/MagneticField',
            CURRENTS: 'sensor_msgs/msg/JointState',
            COMMAND: 'std_msgs/msg/Float64MultiArray',
        }
        assert reader.message_count == 600
        for topic, expected in written.items():
            got = [(stamp, bytes(raw)) for _, stamp, raw in reader.messages([topic])]
            assert got == expected
        decode = reader.deserializer('maglev/currents')
        msg = decode(next(raw for _, _, raw in reader.messages([CURRENTS])))
        assert list(msg.name) == ['x+', 'x-', 'y+', 'y-']
        np.testing.assert_array_equal(msg.effort, run.currents[0])
        assert msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec == run.stamps[0]
        assert reader.metadata == METADATA


def test_rclpy_padding_is_accepted():
    # Fast DDS serialises JointState with trailing bytes; rosbags' strict check rejects them
    raw = currents_msg(5, np.array([1.0, 2.0, 3.0, 4.0]))
    msg = cdr_deserializer(jazzy_typestore(), 'sensor_msgs/msg/JointState')(raw)
    np.testing.assert_array_equal(msg.effort, [1.0, 2.0, 3.0, 4.0])


def test_bag_is_finalised_when_the_block_raises(tmp_path):
    with pytest.raises(RuntimeError, match='boom'):
        with BagWriter(tmp_path / 'b', metadata={'seed': 3}) as bag:
            topic = bag.add_topic('maglev/sensor_0/field', 'sensor_msgs/MagneticField')
            bag.write(topic, 10, field_msg(10, np.ones(3)))
            raise RuntimeError('boom')
    bag.close()  # idempotent, as a signal handler may call it again
    with BagReader(tmp_path / 'b') as reader:
        assert [s for _, s, _ in reader.messages([SENSOR])] == [10]
        assert reader.metadata == {'seed': 3}


def test_writer_rejects_misuse(tmp_path):
    with pytest.raises(BagError, match='unknown bag storage'):
        BagWriter(tmp_path / 'x', storage='rosbag1')
    with pytest.raises(BagError, match='flatten nested'):
        BagWriter(tmp_path / 'x', metadata={'model': {'field': 'fast'}})
    with BagWriter(tmp_path / 'x') as bag:
        topic = bag.add_topic('/a', 'std_msgs/msg/String')
        with pytest.raises(BagError, match="topic '/a' was added"):
            bag.add_topic('a', 'std_msgs/msg/String')
        with pytest.raises(BagError, match='unknown message type'):
            bag.add_topic('/b', 'maglev_msgs/msg/Nope')
        with pytest.raises(BagError, match=r"topic '/c' was not added .*\['/a'\]"):
            bag.write('/c', 1, b'')
    with pytest.raises(BagError, match='is closed'):
        bag.write(topic, 1, b'\x00\x01\x00\x00')
    with pytest.raises(BagError, match='exists already'):
        BagWriter(tmp_path / 'x')


def test_metadata_topic_is_read_too(tmp_path):
    from rclpy.serialization import serialize_message
    from std_msgs.msg import String

    with BagWriter(tmp_path / 'm', metadata={'seed': 1, 'params': 'maggy_v2'}) as bag:
        topic = bag.add_topic('/maglev/metadata', 'std_msgs/msg/String')
        bag.write(topic, 5, serialize_message(String(data='params: maggy_v4\nrate_hz: 5000')))
    with BagReader(tmp_path / 'm') as reader:
        assert reader.metadata == {'seed': 1, 'params': 'maggy_v4', 'rate_hz': 5000}


@pytest.mark.parametrize('storage', STORAGES)
def test_truncated_bag_is_one_clear_error(tmp_path, storage):
    bag = write_lockstep_bag(tmp_path / 'run', lockstep_data(500), storage)
    (store,) = [p for p in bag.iterdir() if p.suffix in ('.mcap', '.db3')]
    data = store.read_bytes()
    store.write_bytes(data[: len(data) // 2])
    with pytest.raises(BagError, match='truncated or corrupt'):
        with BagReader(bag) as reader:
            for _ in reader.messages([SENSOR, CURRENTS]):
                pass


def test_missing_empty_and_unfinished_bags(tmp_path):
    with pytest.raises(BagError, match='does not exist'):
        BagReader(tmp_path / 'nope')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='is empty'):
        BagReader(tmp_path / 'empty')
    (tmp_path / 'unfinished').mkdir()
    (tmp_path / 'unfinished' / 'unfinished.mcap').write_bytes(b'\x89MCAP0\r\n')
    with pytest.raises(BagError, match='no metadata.yaml'):
        BagReader(tmp_path / 'unfinished')
    with BagWriter(tmp_path / 'nomsg', storage='sqlite3') as bag:
        bag.add_topic('/maglev/currents', 'sensor_msgs/msg/JointState')
    with pytest.raises(BagError, match=r"is empty: it has no messages \(topics: \['/maglev/"):
        BagReader(tmp_path / 'nomsg').open()


def test_unknown_topic_lists_the_bags_topics(tmp_path):
    bag = write_lockstep_bag(tmp_path / 'run', lockstep_data(10))
    with BagReader(bag) as reader:
        with pytest.raises(
            BagError,
            match=r"no topic '/maglev/sensor_1/field'; its topics: "
            r'/maglev/currents \(sensor_msgs/msg/JointState\), '
            r'/maglev/currents/command .*/maglev/sensor_0/field',
        ):
            reader.topic('maglev/sensor_1/field')


def test_metadata_added_while_recording(tmp_path):
    with BagWriter(tmp_path / 'r', metadata={'seed': np.int64(1)}) as bag:
        topic = bag.add_topic(SENSOR, 'sensor_msgs/msg/MagneticField')
        bag.write(topic, 1, field_msg(1, np.zeros(3)))
        bag.set_metadata({'stopped_by': 'SIGTERM', 'seed': 2, 'duration_s': 0.5})
    with pytest.raises(BagError, match='is closed'):
        bag.set_metadata({'late': True})
    with BagReader(tmp_path / 'r') as reader:
        assert reader.metadata == {'seed': 2, 'stopped_by': 'SIGTERM', 'duration_s': 0.5}


def test_broken_metadata_and_missing_storage(tmp_path):
    bag = write_lockstep_bag(tmp_path / 'run', lockstep_data(10))
    (bag / 'metadata.yaml').write_text('rosbag2_bagfile_information: [unclosed\n')
    with pytest.raises(BagError, match='its metadata.yaml is invalid'):
        BagReader(bag).open()
    bag = write_lockstep_bag(tmp_path / 'run2', lockstep_data(10))
    (bag / 'run2.mcap').unlink()
    with pytest.raises(BagError, match='its storage file is missing'):
        BagReader(bag).open()


@pytest.mark.parametrize('storage', STORAGES)
def test_write_many_makes_the_bag_write_makes(tmp_path, storage, monkeypatch):
    """The batch path (a tap's burst) gives the same storage file, byte for byte."""
    monkeypatch.setattr('maglev_ros.bags.writer.FLUSH_PERIOD_S', 1e9)  # chunks by size only
    rng = np.random.default_rng(4)
    bursts = []
    for b in range(3000):  # > 1 MiB: the chunk closes inside the run, as write's would
        n = int(rng.integers(1, 8))
        stamps = [b * 10_000 + k for k in range(n)]
        bursts.append((stamps, [bytes(rng.integers(0, 256, 80, dtype=np.uint8)) for _ in stamps]))
    files = []
    for name, many in (('each', False), ('many', True)):  # names of one length
        with BagWriter(tmp_path / name, storage) as writer:
            handles = [writer.add_topic(t, 'sensor_msgs/msg/MagneticField') for t in ('/a', '/b')]
            for i, (stamps, messages) in enumerate(bursts):
                handle = handles[i % 2]
                if many:
                    writer.write_many(handle, stamps, messages)
                else:
                    for stamp, data in zip(stamps, messages, strict=True):
                        writer.write(handle, stamp, data)
            assert writer.message_count == sum(len(s) for s, _ in bursts)
        storage_file = next(p for p in (tmp_path / name).iterdir() if p.suffix != '.yaml')
        files.append((storage_file.read_bytes(), (tmp_path / name / 'metadata.yaml').read_text()))
    if storage == 'mcap':  # the file names are in its summary
        assert files[0][0].replace(b'each', b'many') == files[1][0]
    assert files[0][1].replace('each', 'many') == files[1][1]
    with BagReader(tmp_path / 'many') as reader:
        got = [(stamp, bytes(raw)) for _, stamp, raw in reader.messages(['/a', '/b'])]
    assert got == sorted(
        ((s, d) for stamps, msgs in bursts for s, d in zip(stamps, msgs, strict=True)),
        key=lambda item: item[0],
    )
    with BagWriter(tmp_path / 'bad', storage) as writer:
        handle = writer.add_topic('/a', 'sensor_msgs/msg/MagneticField')
        with pytest.raises(BagError, match='one timestamp per message'):
            writer.write_many(handle, [1, 2], [b'x'])
