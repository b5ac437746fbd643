"""The cores the simulator and driver nodes wire import no ROS (no rclpy, no message packages)."""

import subprocess
import sys

import pytest

CORES = (
    'maglev_ros.physics.session',
    'maglev_ros.physics.session_health',
    'maglev_ros.physics.sample_encoder',
    'maglev_ros.physics.simulator_config',
    'maglev_ros.hardware.command_guard',
    'maglev_ros.hardware.board_stream',
    'maglev_ros.hardware.board_link',
    'maglev_ros.hardware.driver_config',
    'maglev_ros.hardware.driver_health',
    'maglev_ros.cdr',
    'maglev_ros.cdr.batch',
    'maglev_ros.study',
)
ROS = ('rclpy', 'sensor_msgs', 'std_msgs', 'nav_msgs', 'rosgraph_msgs', 'builtin_interfaces')


@pytest.mark.parametrize('module', CORES)
def test_core_imports_no_ros(module):
    code = (
        f'import sys, {module}\n'
        f'print(sorted(m for m in sys.modules if m.split(".")[0] in {ROS!r}))'
    )
    out = subprocess.run(
        [sys.executable, '-c', code], capture_output=True, text=True, check=True, timeout=120
    )
    assert out.stdout.strip() == '[]', f'{module} imports {out.stdout.strip()}'
