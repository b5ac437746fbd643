"""Node parameters through the real ROS 2 command line (issue 11, items 3, 4, 7, 12).

* ``ros2 run maglev_ros <node> --help`` prints the node's parameters, exit 0,
  without starting ROS;
* an integer where a double is expected works (``-p sample_rate:=5000``); any
  other type error is one line naming the parameter, exit 2;
* ``ros2 param dump`` of every node lists every parameter;
* the driver refuses a ``command_timeout`` above the firmware's 1 s watchdog.
"""

from __future__ import annotations

import importlib
import subprocess

import pytest
import yaml
from waiting import wait_for

from .conftest import interrupt

NODES = {  # executable: (node name, module)
    'simulator': ('maglev_simulator', 'maglev_ros.nodes.simulator'),
    'driver': ('maglev_driver', 'maglev_ros.nodes.driver'),
    'excitation': ('maglev_excitation', 'maglev_ros.nodes.excitation'),
    'recorder': ('maglev_recorder', 'maglev_ros.nodes.recorder'),
    'player': ('maglev_player', 'maglev_ros.nodes.player'),
    'identifier': ('maglev_identifier', 'maglev_ros.nodes.identifier'),
    'estimator': ('maglev_estimator', 'maglev_ros.nodes.estimator'),
    'controller': ('maglev_controller', 'maglev_ros.nodes.controller'),
}


def _table(executable):
    return importlib.import_module(NODES[executable][1]).PARAMETERS


def _no_traceback(text):
    assert 'Traceback' not in text and 'Exception' not in text, text


@pytest.mark.parametrize('executable', sorted(NODES))
def test_help_prints_the_parameters_and_exits_0(ros2_env, domain, executable):
    proc = ros2_env.run(['run', 'maglev_ros', executable, '--help'], domain, timeout=60)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith(f'usage: ros2 run maglev_ros {executable} '), proc.stdout
    listed = {line.split()[0] for line in proc.stdout.splitlines()[3:]}
    assert listed == set(_table(executable)), proc.stdout
    _no_traceback(proc.stdout + proc.stderr)


def _bag(tmp_path):
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import MagneticField

    from maglev_ros.bags import BagWriter

    path = tmp_path / 'played'
    with BagWriter(path) as bag:
        topic = bag.add_topic('/maglev/sensor_0/field', 'sensor_msgs/msg/MagneticField')
        for k in range(10):
            bag.write(
                topic, 1_000_000_000 + k * 200_000, bytes(serialize_message(MagneticField()))
            )
    return path


def _start_overrides(executable, tmp_path):
    return {
        'simulator': ['sample_rate:=5000', 'sensor_noise:=0', 'marker_rate:=0'],
        'driver': ['port:=/dev/maglev-none', 'command_timeout:=1', 'supply_voltage:=12'],
        'excitation': ['amplitude:=1', 'sample_rate:=1000'],
        'recorder': [f'path:={tmp_path / "bag"}', "metadata_node:=''", 'depth:=100'],
        'player': [f'path:={_bag(tmp_path)}', 'rate:=1', 'loop:=true', 'start_delay:=0'],
        'identifier': ['forgetting:=1', 'initial_covariance:=10000', 'publish_rate:=2'],
        'estimator': ['sample_rate:=5000', 'gate_probability:=1', 'diagnostics_period:=1'],
        'controller': ['sample_rate:=5000', 'current_limit:=1', 'input_timeout:=1'],
    }[executable]


@pytest.mark.parametrize('executable', sorted(NODES))
def test_integers_for_doubles_run_and_param_dump_is_complete(
    ros2_env, domain, tmp_path, executable
):
    node = NODES[executable][0]
    args = ['run', 'maglev_ros', executable, '--ros-args']
    for item in _start_overrides(executable, tmp_path):
        args += ['-p', item]
    proc = ros2_env.start(args, domain)
    try:
        dumped = {}

        def dump():
            if proc.poll() is not None:
                pytest.fail(f'{executable} exited with {proc.returncode}: {proc.stdout.read()}')
            try:  # a loaded machine answers slowly
                out = ros2_env.run(
                    ['param', 'dump', '--no-daemon', '--spin-time', '1', f'/{node}'],
                    domain,
                    timeout=120,
                )
            except subprocess.TimeoutExpired:
                return False
            if out.returncode != 0 or not out.stdout.strip():
                return False
            dumped.update(yaml.safe_load(out.stdout))
            return True

        wait_for(dump, 300, f'ros2 param dump /{node}', period=0.5)
    finally:
        status, output = interrupt(proc)
    params = dumped[f'/{node}']['ros__parameters']
    assert set(_table(executable)) <= set(params), (set(_table(executable)) - set(params), params)
    assert status == 0, output
    _no_traceback(output)
    if executable == 'simulator':
        assert params['sample_rate'] == 5000 and params['initial_state'] == []


@pytest.mark.parametrize(
    'executable, override, message',
    [
        ('simulator', 'seed:=1.5', 'seed must be an integer, got 1.5'),
        ('simulator', 'sample_rate:=fast', "sample_rate must be a number, got 'fast'"),
        ('simulator', 'mode:=turbo', "mode must be one of realtime, lockstep, got 'turbo'"),
        ('excitation', 'amplitude:=true', 'amplitude must be a number, got True'),
        (
            'driver',
            'command_timeout:=2.0',
            "command_timeout must be at most the firmware's 1 s watchdog",
        ),
        ('identifier', 'forgetting:=1.5', 'forgetting must be a finite number > 0 and <= 1'),
        ('estimator', 'filter:=pf', "filter must be one of kf, ekf, ukf, got 'pf'"),
        ('estimator', 'nis_window:=1', 'nis_window must be an integer >= 2, got 1'),
        ('controller', 'current_limit:=-1', 'current_limit must be a finite number > 0'),
        ('controller', 'start_enabled:=1', 'start_enabled must be true or false, got 1'),
        ('identifier', 'na:=[1,2]', 'na must have 1 or 1*1 = 1 values, got [1, 2]'),
        (
            'identifier',
            "inputs:=['maglev/nowhere:data[0]']",
            "channel topic '/maglev/nowhere' is not in the topic contract",
        ),
    ],
)
def test_other_type_errors_are_one_line_and_exit_2(
    ros2_env, domain, executable, override, message
):
    args = ['run', 'maglev_ros', executable, '--ros-args', '-p', override]
    if executable == 'driver':
        args += ['-p', 'port:=/dev/maglev-none']
    proc = ros2_env.run(args, domain, timeout=120)
    output = proc.stdout + proc.stderr
    assert proc.returncode == 2, output
    # ros2 run adds its own '[ros2run]: Process exited with failure 2'
    lines = [line for line in output.splitlines() if line.strip() and '[ros2run]' not in line]
    assert len(lines) == 1 and message in lines[0], output
