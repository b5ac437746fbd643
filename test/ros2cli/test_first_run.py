"""``ros2 launch`` right after an install: Ctrl-C during the kernels' first compile.

The numba cache is empty (``NUMBA_CACHE_DIR`` a new directory), as after a fresh
``colcon build``: every node compiles its kernels and says so. A Ctrl-C then,
while they compile, must end every process within 2 s of the signal (so
``ros2 launch`` never escalates to SIGTERM or SIGKILL) with status 0, and the
recorder's bag is finalised (``metadata.yaml`` written).
"""

from __future__ import annotations

import re
import time

from .test_launch_files import START_TIMEOUT

STOP_S = 2.0  # s from the Ctrl-C until every launched process has ended
PROGRESS = r'\[\w+-\d+\] maglev_\w+: compiling kernels, first run only: ~\d+ s'


def test_ctrl_c_during_the_first_compile_ends_the_launch_within_2_s(ros2, tmp_path):
    ros2.env['NUMBA_CACHE_DIR'] = str(tmp_path / 'numba')  # empty: nothing compiled yet
    bag = tmp_path / 'lab_bag'
    launch = ros2.start('launch', 'maglev_ros', 'lab.launch.xml', f'bag:={bag}')
    launch.wait_for(PROGRESS, START_TIMEOUT)
    # every node past its imports (a Ctrl-C before a node's main() is Python's own
    # KeyboardInterrupt), the simulator still compiling: stop them now
    launch.wait_for(r'\[maglev_recorder\]: recording', START_TIMEOUT)
    launch.wait_for(r'\[maglev_excitation\]: prbs', START_TIMEOUT)
    assert 'lockstep at' not in launch.output(), 'the simulator compiled already'
    start = time.monotonic()
    launch.interrupt_like_terminal()
    status = launch.wait()
    assert launch.wait_group(timeout=30.0), f'processes of {launch.args} left running'
    took = time.monotonic() - start
    output = launch.output()
    assert took < 30.0, f'ended {took:.1f} s after the Ctrl-C:\n{output[-6000:]}'
    # each node's end after the Ctrl-C, by the launch log's clock
    log = (tmp_path / 'ros_log' / 'latest' / 'launch.log').read_text()
    stamp = r'^(\d+\.\d+) \[\w+\] \[{}\]: {}'
    interrupted = float(re.search(stamp.format('launch', 'user interrupted'), log, re.M)[1])
    ended = {
        m[2]: float(m[1]) - interrupted
        for m in re.finditer(stamp.format(r'(\w+)-\d+', 'process has finished'), log, re.M)
    }
    assert set(ended) == {'simulator', 'excitation', 'recorder'}, log
    assert max(ended.values()) < STOP_S, f's after the Ctrl-C: {ended}\n{log}'
    assert status == 0, output[-6000:]
    assert not re.search(r"sending signal '(SIGTERM|SIGKILL)'", output), output[-6000:]
    exits = launch.launched_exits()
    assert exits and all(code == 0 for code in exits.values()), f'{exits}:\n{output[-6000:]}'
    assert (bag / 'metadata.yaml').is_file(), f'bag not finalised:\n{output[-6000:]}'
