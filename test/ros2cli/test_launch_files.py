"""``ros2 launch`` of each launch file, stopped as a terminal's Ctrl-C stops it.

Each launch runs for at least ``RUN_S`` seconds once its nodes are up; then the
whole process group gets SIGINT (what a terminal sends to its foreground job),
and ``ros2 launch`` forwards its own SIGINT to the nodes after that. Then:

- ``ros2 launch`` and every process it started exit 0;
- no ERROR or FATAL line (and no traceback) appears in the output;
- the bag reads back complete: ``metadata.yaml`` written, every recorded topic
  has messages, the per-topic counts of the index match the messages in the
  file, and the metadata node's parameters are in the bag's metadata.

``lab_board.launch.xml`` needs a board: a ``maglev-virtual-board`` (physics plant,
magnet fixed, 3 sensors) on a pseudo-terminal, started with ``ros2 run``.
"""

from __future__ import annotations

import re
import time
from collections import Counter
from pathlib import Path

import pytest
import yaml

from maglev_ros.bags import BagReader

RUN_S = 5.0  # s of running with the nodes up, before the Ctrl-C
START_TIMEOUT = 180.0  # s: the first start compiles the numba kernels of the install tree
PROBLEMS = re.compile(r'\[(ERROR|FATAL)\]|Traceback|KeyboardInterrupt')


def assert_bag_complete(bag: Path, topics: list[str], metadata_node: str) -> dict[str, int]:
    """Check that ``bag`` reads back complete; return its message count per topic."""
    assert (bag / 'metadata.yaml').is_file(), f'{bag}: no metadata.yaml: {sorted(bag.iterdir())}'
    with BagReader(bag) as reader:
        indexed = {name: info.count for name, info in reader.topics.items()}
        read = Counter(topic for topic, _, _ in reader.messages(list(reader.topics)))
        metadata = reader.metadata
    for topic in topics:
        assert indexed.get(topic, 0) > 0, f'{bag}: no messages on {topic}: {indexed}'
    assert dict(read) == indexed, f'{bag}: index {indexed} but the file holds {dict(read)}'
    keys = sorted(k for k in metadata if k.startswith(f'{metadata_node}.'))
    assert keys, f'{bag}: no {metadata_node} parameters in the metadata: {sorted(metadata)}'
    return indexed


def echo_once(ros2, topic: str):
    """``ros2 topic echo --once TOPIC``, asked again while the topic is not discovered yet.

    Without a daemon, ``ros2 topic echo`` looks the topic's type up once, after a short
    discovery; a publisher it has not seen yet makes it give up at once ("does not
    appear to be published yet"), which says nothing about the launch.
    """
    deadline = time.monotonic() + START_TIMEOUT
    while True:
        echo = ros2.run('topic', 'echo', '--once', topic, timeout=START_TIMEOUT)
        if echo.returncode == 0 or 'does not appear to be published' not in echo.stdout:
            return echo
        if time.monotonic() > deadline:
            return echo
        time.sleep(1.0)


def stop_like_terminal(launch) -> str:
    """Ctrl-C the launch's process group; check every exit status and the output."""
    launch.interrupt_like_terminal()
    status = launch.wait()
    assert launch.wait_group(), f'processes of {launch.args} left running'
    output = launch.output()
    assert status == 0, f'ros2 launch exited with {status}:\n{output[-8000:]}'
    started = launch.launched_processes()
    exits = launch.launched_exits()
    assert started and set(exits) == set(started), (
        f'started {started}, exits reported {exits}:\n{output[-8000:]}'
    )
    failed = {name: code for name, code in exits.items() if code != 0}
    assert not failed, f'processes exited non-zero {failed}:\n{output[-8000:]}'
    problems = [line for line in output.splitlines() if PROBLEMS.search(line)]
    assert not problems, 'errors in the output:\n' + '\n'.join(problems[:40])
    return output


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_lab_launch_records_and_stops_cleanly_on_ctrl_c(ros2, tmp_path, storage):
    bag = tmp_path / 'lab_bag'
    launch = ros2.start(
        'launch', 'maglev_ros', 'lab.launch.xml', 'magnet:=fixed', f'bag:={bag}',
        f'storage:={storage}',
    )  # fmt: skip
    launch.wait_for(r'\[maglev_recorder\]: recording', START_TIMEOUT)
    launch.wait_for(r'\[maglev_simulator\]: .* lockstep at', START_TIMEOUT)
    time.sleep(RUN_S)
    stop_like_terminal(launch)
    counts = assert_bag_complete(
        bag,
        ['/maglev/sensor_0/field', '/maglev/currents', '/maglev/currents/command', '/clock'],
        'maglev_simulator',
    )
    # lockstep: one field and one applied current per sample (the stop may fall between)
    assert abs(counts['/maglev/sensor_0/field'] - counts['/maglev/currents']) <= 1, counts


def test_lab_board_launch_records_and_stops_cleanly_on_ctrl_c(ros2, tmp_path):
    board = ros2.start(
        'run', 'maglev_ros', 'maglev-virtual-board', '--sensors', '3', '--plant', 'physics',
        '--magnet', 'fixed', '--link', str(tmp_path / 'ttyMAGGY'),
    )  # fmt: skip
    port = board.wait_for(r'^(/\S+)$', START_TIMEOUT)[1]
    bag = tmp_path / 'board_bag'
    launch = ros2.start(
        'launch', 'maglev_ros', 'lab_board.launch.xml', f'port:={port}', f'bag:={bag}'
    )
    launch.wait_for(r'\[maglev_recorder\]: recording', START_TIMEOUT)
    launch.wait_for(r'\[maglev_driver\]: connected to', START_TIMEOUT)
    # the driver publishes once its link has caught up: wait for the first sample
    echo = echo_once(ros2, '/maglev/currents')
    assert echo.returncode == 0 and 'effort' in echo.stdout, echo.stdout + echo.stderr
    time.sleep(RUN_S)
    stop_like_terminal(launch)
    board.interrupt_like_terminal()
    assert board.wait() == 0, board.output()
    assert_bag_complete(
        bag,
        ['/maglev/sensor_0/field', '/maglev/currents', '/maglev/currents/command'],
        'maglev_driver',
    )


def test_closed_loop_launch_levitates_and_stops_cleanly_on_ctrl_c(ros2, tmp_path):
    launch = ros2.start('launch', 'maglev_ros', 'closed_loop.launch.xml')
    launch.wait_for(r'\[maglev_simulator\]: .* realtime at', START_TIMEOUT)
    launch.wait_for(r'\[maglev_controller\]: lqr on', START_TIMEOUT)
    echo = ros2.run('topic', 'echo', '--once', '/maglev/state/estimate', timeout=START_TIMEOUT)
    assert echo.returncode == 0 and 'pose' in echo.stdout, echo.stdout + echo.stderr
    time.sleep(RUN_S)
    state = ros2.run('topic', 'echo', '--once', '/maglev/state/true', timeout=START_TIMEOUT)
    assert state.returncode == 0, state.stdout + state.stderr
    position = yaml.safe_load(state.stdout.split('---')[0])['pose']['pose']['position']
    assert abs(position['x']) < 1e-3 and abs(position['y']) < 1e-3, position  # still held
    assert position['z'] > 0.03, position
    stop_like_terminal(launch)
