"""The driver's settings joined into one configuration, without ROS."""

import pytest

from maglev_ros.hardware.driver_config import DriverConfigError, DriverSettings, driver_config
from maglev_ros.hardware.scaling import BOARD_COIL_RESISTANCE, BOARD_SUPPLY_VOLTAGE
from maglev_ros.parameters import config_params

VALUES = {
    'port': '/dev/ttyACM0',
    'firmware': 'v2x',
    'baudrate': 0,
    'n_sensors': 2,
    'sensor_frames': (),
    'supply_voltage': BOARD_SUPPLY_VOLTAGE,
    'coil_resistance': BOARD_COIL_RESISTANCE,
    'counts_per_ampere': 0.0,
    'current_limit': 0.0,
    'command_timeout': 0.1,
    'start_enabled': False,
    'reconnect_min_delay': 0.2,
    'reconnect_max_delay': 5.0,
    'diagnostics_period': 1.0,
    'confirm_records': True,
    'read_interval': 0.0,
}


def test_defaults_fill_frames_baud_scaling_and_limit():
    config = driver_config(VALUES)
    assert config.sensor_frames == ('maglev_sensor_0', 'maglev_sensor_1')
    assert config.baudrate == 9600
    assert config.scaling.counts_per_ampere == pytest.approx(
        4096 * BOARD_COIL_RESISTANCE / BOARD_SUPPLY_VOLTAGE
    )
    assert config.current_limit == pytest.approx(config.scaling.max_current)
    assert driver_config(VALUES | {'firmware': 'v4x'}).baudrate == 115200


def test_explicit_values_win():
    config = driver_config(
        VALUES
        | {'baudrate': 57600, 'counts_per_ampere': 1000.0, 'current_limit': 0.5}
        | {'sensor_frames': ('a', 'b')}
    )
    assert config.baudrate == 57600 and config.sensor_frames == ('a', 'b')
    assert config.scaling.counts_per_ampere == 1000.0 and config.current_limit == 0.5


@pytest.mark.parametrize(
    ('changes', 'match'),
    [
        (
            {'sensor_frames': ('a',)},
            r"sensor_frames must name 2 frames \(n_sensors\), got \['a'\]",
        ),
        ({'reconnect_max_delay': 0.1}, r'reconnect_max_delay must be >= reconnect_min_delay'),
        (
            {'firmware': 'v4x_pc'},
            r'n_sensors must be 1 for the V4x PC-control firmware \(it reads one sensor\), got 2',
        ),
    ],
)
def test_settings_that_do_not_fit_together(changes, match):
    with pytest.raises(DriverConfigError, match=match):
        driver_config(VALUES | changes)


def test_limit_above_full_scale_names_both():
    with pytest.raises(
        DriverConfigError, match=r"current_limit 3.5 A is above the board's full scale 3 A"
    ):
        driver_config(VALUES | {'current_limit': 3.5})  # 4096 counts at 1365 counts/A


def test_v4x_pc_scaling_is_8_bit():
    config = driver_config(VALUES | {'firmware': 'v4x_pc', 'n_sensors': 1, 'sensor_frames': ()})
    assert config.scaling.full_scale == 255
    assert config.scaling.counts_per_ampere == pytest.approx(85.0)
    assert config.current_limit == pytest.approx(3.0)
    assert config.baudrate == 115200
    assert config.poll_rate == 1000.0  # the default: above the lab host's 800 Hz


def test_settings_declare_each_parameter_once_with_its_rule():
    settings = DriverSettings()  # the defaults pass their own rules
    assert settings.sensor_frames == () and settings.command_timeout == 0.1
    params = config_params(DriverSettings)
    assert set(VALUES) | {'poll_rate'} == set(params)
    assert params['current_limit'].mutable and not params['port'].mutable
    assert 'watchdog' in params['command_timeout'].constraints
    assert DriverSettings(sensor_frames=('a', '', 'b')).sensor_frames == ('a', 'b')
    assert DriverSettings(supply_voltage=12).supply_voltage == 12.0  # an integer for a double


@pytest.mark.parametrize(
    'changes, match',
    [
        ({'command_timeout': 1.5}, r"command_timeout must be at most the firmware's 1 s watchdog"),
        ({'command_timeout': -1.0}, 'command_timeout must be a positive finite number'),
        ({'poll_rate': 50.0}, r'poll_rate must be 0 \(as fast as the board answers\) or in 100'),
        ({'read_interval': 0.1}, r'read_interval must be in 0 .. 0.05 s, got 0.1'),
        ({'firmware': 'v5x'}, r"firmware must be 'v2x', 'v4x' or 'v4x_pc'"),
        ({'port': ''}, 'port must be a device path'),
        ({'n_sensors': 2.5}, 'n_sensors must be an integer, got 2.5'),
    ],
)
def test_a_setting_against_its_rule_is_refused_by_name(changes, match):
    with pytest.raises(DriverConfigError, match=match):
        DriverSettings(**changes)
