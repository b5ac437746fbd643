"""The writer's close semantics as a recorder uses them: signals and several threads."""

import signal
import subprocess
import sys
import textwrap
import threading

import numpy as np
import pytest

from maglev_ros.bags import BagReader, BagWriter

from .recordings import SENSOR, field_msg

RECORDER = textwrap.dedent("""
    import signal, sys
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import MagneticField
    from maglev_ros.bags import BagWriter

    # SIGTERM ends the process like Ctrl-C does: the with block unwinds and closes the bag.
    # Ctrl-C raises KeyboardInterrupt even if this process inherited an ignored SIGINT
    # (a test run started in the background by a non-interactive shell).
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    signal.signal(signal.SIGINT, signal.default_int_handler)
    with BagWriter(sys.argv[1], storage=sys.argv[2], metadata={'seed': 7}) as bag:
        topic = bag.add_topic('/maglev/sensor_0/field', 'sensor_msgs/msg/MagneticField')
        k = 0
        while True:
            msg = MagneticField()
            msg.header.stamp.nanosec = k
            bag.write(topic, k, serialize_message(msg))
            k += 1
            if k == 200:
                print('recording', flush=True)
""")


@pytest.mark.parametrize(
    ('storage', 'sig'), [('mcap', signal.SIGTERM), ('sqlite3', signal.SIGINT)]
)
def test_bag_is_readable_after_a_signal(tmp_path, storage, sig):
    path = tmp_path / 'rec'
    proc = subprocess.Popen(
        [sys.executable, '-c', RECORDER, str(path), storage],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        assert proc.stdout.readline().strip() == 'recording'
        proc.send_signal(sig)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    with BagReader(path) as reader:
        stamps = [s for _, s, _ in reader.messages([SENSOR])]
        assert len(stamps) >= 200
        assert stamps == list(range(len(stamps)))  # every message, in order
        assert reader.metadata == {'seed': 7}


def test_threads_write_while_another_closes(tmp_path):
    bag = BagWriter(tmp_path / 'mt', storage='sqlite3').open()
    topics = [
        bag.add_topic(f'/maglev/sensor_{k}/field', 'sensor_msgs/msg/MagneticField')
        for k in range(3)
    ]
    raw = field_msg(1, np.zeros(3))

    def publish(topic):
        for k in range(300):
            bag.write(topic, k, raw)

    threads = [threading.Thread(target=publish, args=(t,)) for t in topics]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    bag.close()
    bag.close()
    with BagReader(tmp_path / 'mt') as reader:
        assert {t: i.count for t, i in reader.topics.items()} == {
            f'/maglev/sensor_{k}/field': 300 for k in range(3)
        }


def test_an_exception_inside_a_record_leaves_no_partial_record(tmp_path, monkeypatch):
    """A signal handler's exception between two fields of a record (MCAP) writes none of it."""
    import rosbags.rosbag2.storage_mcap as mcap

    original = mcap.write_record
    calls = {'n': 0}

    def interrupted(bio, op, record):
        calls['n'] += 1
        if calls['n'] == 50:  # the record's opcode is out, its length not yet
            bio.write(op.to_bytes(1, byteorder='little'))
            raise SystemExit(0)
        return original(bio, op, record)

    monkeypatch.setattr(mcap, 'write_record', interrupted)
    path = tmp_path / 'rec'
    with pytest.raises(SystemExit), BagWriter(path, storage='mcap') as bag:
        topic = bag.add_topic(SENSOR, 'sensor_msgs/msg/MagneticField')
        for k in range(100):
            bag.write(topic, k, field_msg(k, (0.0, 0.0, 0.0)))
    with BagReader(path) as reader:
        stamps = [s for _, s, _ in reader.messages([SENSOR])]
    assert stamps == list(range(len(stamps))) and 40 <= len(stamps) < 50
