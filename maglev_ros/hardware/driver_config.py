"""The board driver's configuration, ROS-free: its settings, their rules and defaults.

:class:`DriverSettings` declares each setting once (default, description with
unit, rule: :func:`maglev_ros.parameters.setting`); the driver node's parameter
table comes from it. :func:`driver_config` then applies the rules that join
several (frames per sensor, the scaling, the back-off bounds, the firmware's
default baud rate) and builds the frozen :class:`DriverConfig`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from ..parameters import NodeParameterError, check_settings, integer, setting
from ..topics import DIAGNOSTICS_TOPIC, sensor_frame
from .packet import PWM_FULL_SCALE, WATCHDOG_S
from .scaling import (
    BOARD_COIL_RESISTANCE,
    BOARD_SUPPLY_VOLTAGE,
    V4X_PWM_FULL_SCALE,
    CurrentScaling,
)
from .v4x_pc_poller import DEFAULT_POLL_RATE

__all__ = [
    'DEFAULT_BAUD',
    'MAX_POLL_RATE',
    'MAX_READ_INTERVAL_S',
    'DriverConfig',
    'DriverConfigError',
    'DriverSettings',
    'driver_config',
]

DEFAULT_BAUD = {'v2x': 9600, 'v4x': 115200, 'v4x_pc': 115200}  # ignored by USB CDC, set anyway
MAX_READ_INTERVAL_S = 0.05  # s: 50 ms of 3-sensor V2x data is 12 KB, inside a pty's buffer
MAX_POLL_RATE = 5000.0  # Hz: the V4x PC-control board samples every 200 us


def _rule(*rules: tuple[Callable[[object], bool], str]):
    """Return a check of ``(test, words)`` pairs: the first failing one "must be WORDS"."""

    def check(name: str, value):
        for test, words in rules:
            if not test(value):
                raise NodeParameterError(f'{name} must be {words}, got {value!r}')
        return value

    check.rule = '; '.join(words for _, words in rules)
    return check


def _positive(v: float) -> bool:
    return math.isfinite(v) and v > 0


_POSITIVE = (_positive, 'a positive finite number')
_POSITIVE_OR_ZERO = (lambda v: v == 0 or _positive(v), 'a positive finite number or 0')


def _frames(name: str, value: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(f for f in value if f)  # empty strings: the default frame


@dataclass(frozen=True)
class DriverSettings:
    """The driver's settings as a user gives them (the driver node's parameters).

    Constructing it applies each setting's rule (:class:`DriverConfigError`);
    :func:`driver_config` joins them.
    """

    port: str = setting(
        '/dev/ttyACM0',
        'serial device path (a udev symlink is best)',
        _rule((bool, 'a device path')),
    )
    firmware: str = setting(
        'v2x',
        "board firmware: 'v2x' (binary stream), 'v4x' (text, read only) or 'v4x_pc' "
        '(V4x PC control, COBS request/response)',
        _rule((DEFAULT_BAUD.__contains__, "'v2x', 'v4x' or 'v4x_pc' (V4x PC control)")),
    )
    baudrate: int = setting(
        0,
        'baud rate; 0: 9600 for v2x, 115200 for v4x',
        _rule((lambda v: v >= 0, ">= 0 (0: the firmware's default)")),
    )
    n_sensors: int = setting(
        1, 'number of sensors per record (not announced by the board)', integer(1, 64)
    )
    sensor_frames: tuple[str, ...] = setting(
        (), f'frame id per sensor; empty: {sensor_frame("<k>")}', _frames, kind='string_array'
    )
    supply_voltage: float = setting(
        BOARD_SUPPLY_VOLTAGE, 'H-bridge supply voltage in V (V2x scaling)', _rule(_POSITIVE)
    )
    coil_resistance: float = setting(
        BOARD_COIL_RESISTANCE,
        'coil resistance in ohm, wiring included (V2x scaling)',
        _rule(_POSITIVE),
    )
    counts_per_ampere: float = setting(
        0.0, 'PWM counts per A; > 0 overrides voltage/resistance', _rule(_POSITIVE_OR_ZERO)
    )
    current_limit: float = setting(
        0.0,
        'largest commanded |current| in A; 0: full duty (V/R)',
        _rule(_POSITIVE_OR_ZERO),
        mutable=True,
    )
    command_timeout: float = setting(
        0.1,
        f"s without a valid command before zero currents (at most the firmware's "
        f'{WATCHDOG_S:g} s watchdog)',
        _rule(
            _POSITIVE,
            (
                lambda v: v <= WATCHDOG_S,
                f"at most the firmware's {WATCHDOG_S:g} s watchdog (the board zeroes its PWM "
                'after that long without a packet)',
            ),
        ),
        mutable=True,
    )
    start_enabled: bool = setting(False, 'enable state at start-up (disabled: zero currents)')
    reconnect_min_delay: float = setting(
        0.2, 's, first delay before reopening the port', _rule(_POSITIVE)
    )
    reconnect_max_delay: float = setting(
        5.0, 's, longest delay between reopen attempts', _rule(_POSITIVE)
    )
    diagnostics_period: float = setting(
        1.0, f's between {DIAGNOSTICS_TOPIC} messages', _rule(_POSITIVE)
    )
    confirm_records: bool = setting(
        True,
        'V2x: hold the newest record until the next confirms it (a cut record is then '
        'dropped, not published corrupted; up to 1 ms more latency for the last record '
        'of each burst); false: publish at once',
    )
    read_interval: float = setting(
        0.0,
        's, shortest time between reads of the port (0: every burst as it arrives; '
        '0.002: two 1 ms bursts per read, less CPU, up to 2 ms more latency)',
        _rule((lambda v: 0.0 <= v <= MAX_READ_INTERVAL_S, f'in 0 .. {MAX_READ_INTERVAL_S} s')),
    )
    poll_rate: float = setting(
        DEFAULT_POLL_RATE,
        'v4x_pc: Hz, steps (read field and currents, write the command) per second; '
        '0: as fast as the board answers',
        _rule(
            (
                lambda v: v == 0 or 100.0 <= v <= MAX_POLL_RATE,
                f'0 (as fast as the board answers) or in 100 .. {MAX_POLL_RATE:g} Hz (the '
                'board samples at 5 kHz)',
            )
        ),
    )

    def __post_init__(self) -> None:
        check_settings(self, DriverConfigError)


class DriverConfigError(ValueError):
    """Driver settings do not fit together (the message names the value)."""


@dataclass(frozen=True)
class DriverConfig:
    """Validated driver parameters (meanings: the driver node's module docstring).

    Attributes
    ----------
    port : str
        Serial device path.
    firmware : str
        ``'v2x'``, ``'v4x'`` or ``'v4x_pc'`` (V4x PC control: 8-bit PWM scaling).
    baudrate : int
        Baud rate.
    n_sensors : int
        Sensors per record or line.
    sensor_frames : tuple of str
        Frame id of each sensor's field messages.
    scaling : CurrentScaling
        Current to PWM map (V2x).
    current_limit : float
        Largest commanded current magnitude in A.
    command_timeout : float
        s without a valid command before zero currents are sent.
    start_enabled : bool
        Enable state at start-up.
    reconnect_min_delay, reconnect_max_delay : float
        Back-off bounds in s for reopening the port.
    diagnostics_period : float
        s between diagnostics messages.
    confirm_records : bool
        Hold the newest V2x record of each read until the next record
        confirms its boundary (see ``hardware.v2x_stream``).
    read_interval : float
        Shortest time in s between reads of the port (0: read as soon as data
        arrives, every burst).
    poll_rate : float
        V4x PC control: steps (read sensors and currents, write the command)
        per second; 0: as fast as the board answers.
    """

    port: str
    firmware: str
    baudrate: int
    n_sensors: int
    sensor_frames: tuple[str, ...]
    scaling: CurrentScaling
    current_limit: float
    command_timeout: float
    start_enabled: bool
    reconnect_min_delay: float
    reconnect_max_delay: float
    diagnostics_period: float
    confirm_records: bool = True
    read_interval: float = 0.0
    poll_rate: float = DEFAULT_POLL_RATE


def driver_config(v: Mapping[str, object]) -> DriverConfig:
    """Build a ``DriverConfig`` from parameter values checked one by one.

    Parameters
    ----------
    v : mapping
        Every driver parameter by name (the node's table: ``port``,
        ``firmware``, ``baudrate`` (0: the firmware's default),
        ``n_sensors``, ``sensor_frames`` (empty: the default frames),
        ``supply_voltage``, ``coil_resistance``, ``counts_per_ampere`` (0: from
        voltage and resistance), ``current_limit`` (0: full duty), ...).

    Returns
    -------
    DriverConfig
        The validated configuration.

    Raises
    ------
    DriverConfigError
        More than one sensor for V4x PC control, frames not one per sensor, a
        current limit above the scaling's full scale, or a back-off maximum
        below its minimum.
    """
    n_sensors = v['n_sensors']
    if v['firmware'] == 'v4x_pc' and n_sensors != 1:
        raise DriverConfigError(
            f'n_sensors must be 1 for the V4x PC-control firmware (it reads one sensor), '
            f'got {n_sensors}'
        )
    frames = v['sensor_frames'] or tuple(sensor_frame(k) for k in range(n_sensors))
    if len(frames) != n_sensors:
        raise DriverConfigError(
            f'sensor_frames must name {n_sensors} frames (n_sensors), got {list(frames)}'
        )
    # the V4x PC-control firmware takes 8-bit PWM, the V2x firmware 12-bit
    full_scale = V4X_PWM_FULL_SCALE if v['firmware'] == 'v4x_pc' else PWM_FULL_SCALE
    if v['counts_per_ampere']:
        scaling = CurrentScaling(v['counts_per_ampere'], full_scale)
    else:
        scaling = CurrentScaling.from_supply(v['supply_voltage'], v['coil_resistance'], full_scale)
    if v['current_limit'] > scaling.max_current * (1 + 1e-9):
        raise DriverConfigError(
            f"current_limit {v['current_limit']:g} A is above the board's full scale "
            f'{scaling.max_current:.4g} A (from the scaling: {scaling.counts_per_ampere:.4g} '
            f'counts/A, {scaling.full_scale} counts at full duty); lower current_limit '
            '(0: the full scale) or fix the scaling'
        )
    min_delay, max_delay = v['reconnect_min_delay'], v['reconnect_max_delay']
    if max_delay < min_delay:
        raise DriverConfigError(
            f'reconnect_max_delay must be >= reconnect_min_delay ({min_delay}), got {max_delay}'
        )
    return DriverConfig(
        port=v['port'],
        firmware=v['firmware'],
        baudrate=v['baudrate'] or DEFAULT_BAUD[v['firmware']],
        n_sensors=n_sensors,
        sensor_frames=frames,
        scaling=scaling,
        current_limit=v['current_limit'] or scaling.max_current,
        command_timeout=v['command_timeout'],
        start_enabled=v['start_enabled'],
        reconnect_min_delay=min_delay,
        reconnect_max_delay=max_delay,
        diagnostics_period=v['diagnostics_period'],
        confirm_records=v['confirm_records'],
        read_interval=v['read_interval'],
        poll_rate=float(v.get('poll_rate', DEFAULT_POLL_RATE)),
    )
