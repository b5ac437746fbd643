"""Issue 11 item 9: a recording killed with SIGKILL is rebuilt, losing at most ~1 s.

A child process records with BagWriter (the recorder's writer) at 1 kHz, each
message carrying its sequence number; the test kills it with SIGKILL, rebuilds
the bag with ``maglev-bag2data --reindex`` and reads it back: an unbroken run of
messages from the first, the last written less than ~1 s before the kill.
"""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from maglev_ros.bags import BagError, BagReader, reindex
from maglev_ros.cli import bag2data

CHILD = r"""
import sys, time
import numpy as np
from maglev_ros.bags import BagWriter
with BagWriter(sys.argv[1], sys.argv[2]) as writer:
    handle = writer.add_topic('/maglev/currents/command', 'std_msgs/msg/Float64MultiArray')
    header = bytes([0, 1, 0, 0]) + (0).to_bytes(4, 'little') + (0).to_bytes(4, 'little')
    k = 0
    while True:
        now = time.time_ns()
        payload = header + (4).to_bytes(4, 'little') + np.array([k, now, 0, 0], '<f8').tobytes()
        writer.write(handle, now, payload)
        if k == 0:
            print('recording', flush=True)
        k += 1
        time.sleep(0.001)
"""


def values(raw: bytes) -> np.ndarray:
    return np.frombuffer(raw[-32:], '<f8')


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_sigkilled_recording_is_rebuilt_losing_at_most_its_last_second(tmp_path, storage, capsys):
    bag = tmp_path / 'killed'
    child = subprocess.Popen(
        [sys.executable, '-c', CHILD, str(bag), storage], stdout=subprocess.PIPE, text=True
    )
    assert child.stdout.readline().strip() == 'recording'
    time.sleep(3.5)
    killed_ns = time.time_ns()
    os.kill(child.pid, signal.SIGKILL)
    child.wait()
    child.stdout.close()
    with pytest.raises(BagError, match='maglev-bag2data --reindex'):
        BagReader(bag)

    assert bag2data.main([str(bag), '--reindex']) == 0
    assert 'rebuilt from' in capsys.readouterr().out

    with BagReader(bag) as reader:
        rows = np.array([values(raw) for _, _, raw in reader.messages(reader.topics)])
        assert reader.metadata['reindexed_from'].startswith('killed')
    sequence, stamps = rows[:, 0], rows[:, 1]
    np.testing.assert_array_equal(sequence, np.arange(len(rows)))  # unbroken, intact
    assert len(rows) > 1000
    assert killed_ns - stamps[-1] < 1.3e9, f'lost {(killed_ns - stamps[-1]) * 1e-9:.2f} s'
    assert any(p.name.endswith('.damaged') for p in bag.iterdir())


def test_truncated_mcap_keeps_every_complete_message(tmp_path):
    """A file cut anywhere (power loss): everything before the cut is salvaged."""
    from maglev_ros.bags import BagWriter
    from maglev_ros.bags.reindex import salvage_mcap

    bag = tmp_path / 'whole'
    with BagWriter(bag) as writer:
        handle = writer.add_topic('/a', 'std_msgs/msg/Float64MultiArray')
        for k in range(300):
            writer.write(handle, k, bytes(12) + np.array([k], '<f8').tobytes())
            if k % 100 == 99:
                writer.flush()  # three chunks
    data = next(bag.glob('*.mcap')).read_bytes()
    whole = salvage_mcap(next(bag.glob('*.mcap')))
    assert len(whole.messages) == 300
    cut_bag = tmp_path / 'cut'
    cut_bag.mkdir()
    cut = cut_bag / 'cut.mcap'
    cut.write_bytes(data[: len(data) // 2])
    part = salvage_mcap(cut)
    assert 0 < len(part.messages) < 300
    assert [m[1] for m in part.messages] == list(range(len(part.messages)))
    report = reindex(cut_bag)
    assert report.counts == {'/a': len(part.messages)} and report.lost_bytes > 0
    with BagReader(cut_bag) as reader:
        assert reader.message_count == len(part.messages)


def test_finished_bag_is_left_alone(tmp_path):
    from maglev_ros.bags import BagWriter

    bag = tmp_path / 'done'
    with BagWriter(bag) as writer:
        writer.write(writer.add_topic('/a', 'std_msgs/msg/Float64MultiArray'), 1, bytes(12))
    with pytest.raises(BagError, match='is finished'):
        reindex(bag)
