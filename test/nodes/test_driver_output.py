"""The driver tests leave nothing in pytest's output: a driver lets go of its board first.

A driver test's board used to close before the driver node (the board is the test's
``with`` block, the driver the fixture's teardown): the driver's I/O thread then
logged the lost link, often between pytest's capture phases, so ``[WARN] ... link
lost`` lines ran into the progress dots. The check runs one driver test in a pytest
of its own with every captured section shown (``-rA``): no lost link, captured or not.
"""

import os
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def test_a_driver_test_ends_without_a_lost_link(domain):
    done = subprocess.run(
        [
            sys.executable,
            '-m',
            'pytest',
            '-q',
            '-rA',
            '-p',
            'no:cacheprovider',
            str(HERE / 'test_driver.py') + '::test_disabled_means_zero_currents',
        ],
        cwd=HERE.parents[1],
        env=dict(os.environ, ROS_DOMAIN_ID=str(domain)),
        capture_output=True,
        text=True,
        timeout=240,
        check=False,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert '1 passed' in output, output
    assert 'link lost' not in output, output
