"""Byte-exact emulators of the Maggy board firmware (ROS-free, no I/O).

The emulators run on an explicit clock: ``advance_to(t_us)`` runs the
board's loop up to time ``t_us`` (microseconds since power-up) and returns
the bytes the board wrote meanwhile; ``receive(data)`` hands over bytes
from the host, which the loop parses at its next sample tick. A pacing
layer (``virtual_board``) ties the clock to the wall clock and a serial
device.

Behind each emulator sits a *plant*: any callable mapping the applied PWM
counts, shape (4,) (x+, x-, y+, y-), and the time in s to the sensor fields
in millitesla, shape (n_sensors, 3). ``LinearPlant`` is a simple one
(field = offset + gain @ pwm); the physics core plugs in the same way.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .packet import PWM_FULL_SCALE, WATCHDOG_S, CommandParser
from .scaling import CurrentScaling
from .v2x_stream import BURST_RECORDS, SAMPLE_PERIOD_US, pack_records
from .v4x_telemetry import format_telemetry_line

__all__ = [
    'Plant',
    'LinearPlant',
    'V2xFirmware',
    'V4xFirmware',
]

Plant = Callable[[NDArray[np.int64], float], ArrayLike]
"""Plant signature: ``plant(pwm_counts (4,), time_s) -> field_mT (n_sensors, 3)``."""

STARTUP_DELAY_US = 2_000_000  # us: the sketch waits ~2 s before its loop runs
WATCHDOG_US = round(WATCHDOG_S * 1e6)  # us without an accepted packet before the PWM is zeroed
_CLOCK_WRAP = 1 << 32  # us


@dataclass(frozen=True)
class LinearPlant:
    """Sensor fields linear in the applied PWM: ``B = offset + gain @ pwm``.

    Parameters
    ----------
    offset_mT : array_like, shape (n_sensors, 3)
        Field at zero PWM in mT (permanent magnets, levitating magnet).
    gain_mT_per_count : array_like, shape (n_sensors, 3, 4)
        Field per PWM count of each coil (x+, x-, y+, y-), mT per count.
    """

    offset_mT: NDArray[np.float64]  # noqa: N815 (unit symbol mT)
    gain_mT_per_count: NDArray[np.float64]  # noqa: N815 (unit symbol mT)

    def __post_init__(self) -> None:
        offset = np.array(self.offset_mT, dtype=float)
        gain = np.array(self.gain_mT_per_count, dtype=float)
        if offset.ndim != 2 or offset.shape[1] != 3:
            raise ValueError(f'offset_mT must have shape (n_sensors, 3), got {offset.shape}')
        if gain.shape != offset.shape + (4,):
            raise ValueError(
                f'gain_mT_per_count must have shape {offset.shape + (4,)}, got {gain.shape}'
            )
        object.__setattr__(self, 'offset_mT', offset)
        object.__setattr__(self, 'gain_mT_per_count', gain)

    @classmethod
    def default(cls, n_sensors: int = 1) -> LinearPlant:
        """Build a plausible Maggy-like plant for ``n_sensors`` sensors.

        Sensor k reads a permanent-magnet field of about 40 mT vertical and
        a few mT horizontal; each coil adds up to about 8 mT at full duty,
        mostly vertical, with a sign pattern that distinguishes the coils.

        Parameters
        ----------
        n_sensors : int
            Number of sensors (>= 1).

        Returns
        -------
        LinearPlant
            The plant.
        """
        if n_sensors < 1:
            raise ValueError(f'n_sensors must be >= 1, got {n_sensors}')
        k = np.arange(n_sensors, dtype=float)[:, None]
        offset = np.hstack([0.5 + 0.25 * k, -0.3 + 0.1 * k, 40.0 - 2.0 * k])
        coil_sign = np.array([1.0, -1.0, 0.5, -0.5])  # x+, x-, y+, y-
        per_axis = np.array([0.4, 0.3, 2.0])[:, None] * coil_sign  # mT at full duty / 4
        gain = np.stack([per_axis * (1.0 + 0.1 * j) for j in range(n_sensors)])
        return cls(offset, gain * 4.0 / PWM_FULL_SCALE)

    @property
    def n_sensors(self) -> int:
        """Number of sensors."""
        return self.offset_mT.shape[0]

    def __call__(self, pwm: ArrayLike, time: float) -> NDArray[np.float64]:
        """Return the fields in mT, shape (n_sensors, 3), for PWM counts (4,)."""
        return self.offset_mT + self.gain_mT_per_count @ np.asarray(pwm, dtype=float)


@dataclass
class _Loop:
    """Loop timing shared by the emulators (times in us since power-up)."""

    now_us: int = 0
    next_tick_us: int = STARTUP_DELAY_US
    startup_delay_us: int = STARTUP_DELAY_US
    resume_us: int = STARTUP_DELAY_US  # end of the current start-up wait
    tampers: deque = field(default_factory=deque)

    def suspend(self) -> None:
        """Restart the start-up wait from now (port opened)."""
        self.resume_us = max(self.next_tick_us, self.now_us + self.startup_delay_us)
        self.next_tick_us = self.resume_us

    @property
    def running(self) -> bool:
        """Whether the loop runs (not in a start-up wait)."""
        return self.now_us >= self.resume_us


def _check_delay(name: str, seconds: float) -> int:
    if not seconds >= 0:
        raise ValueError(f'{name} must be >= 0 s, got {seconds!r}')
    return round(seconds * 1e6)


class V2xFirmware:
    """Emulator of the V2x "PC interface" firmware.

    Parameters
    ----------
    plant : callable
        ``plant(pwm_counts (4,), time_s) -> field_mT (n_sensors, 3)``.
    n_sensors : int
        Sensors per record (>= 1).
    clock_start_us : int, optional
        Value of the board's uint32 microsecond clock at power-up (use a
        value near 2**32 to test the wrap-around).
    startup_delay : float, optional
        Seconds the loop waits after power-up and after each port open.
    watchdog : float, optional
        Seconds without an accepted packet after which the PWM is zeroed.

    Notes
    -----
    Each sample tick (every 200 us once the loop runs): parse the bytes
    received so far (``CommandParser``; an accepted packet sets the PWM,
    clamped to +-4096, and feeds the watchdog), zero the PWM once if the
    watchdog expired, evaluate the plant, and store a record with the
    clock and the PWM in force. Every fifth tick the five records are
    written back to back.
    """

    def __init__(
        self,
        plant: Plant,
        n_sensors: int = 1,
        *,
        clock_start_us: int = 0,
        startup_delay: float = 2.0,
        watchdog: float = 1.0,
    ) -> None:
        if not callable(plant):
            raise TypeError(f'plant must be callable, got {type(plant).__name__}')
        if not isinstance(n_sensors, int) or n_sensors < 1:
            raise ValueError(f'n_sensors must be an int >= 1, got {n_sensors!r}')
        if not 0 <= int(clock_start_us) < _CLOCK_WRAP:
            raise ValueError(f'clock_start_us must be in 0 .. 2**32 - 1, got {clock_start_us}')
        self.plant = plant
        self.n_sensors = n_sensors
        self.clock_start_us = int(clock_start_us)
        delay = _check_delay('startup_delay', startup_delay)
        self._loop = _Loop(next_tick_us=delay, startup_delay_us=delay, resume_us=delay)
        self._watchdog_us = _check_delay('watchdog', watchdog)
        self._parser = CommandParser()
        self._input = bytearray()
        self._pwm = np.zeros(4, dtype=np.int64)
        self._last_accept_us: int | None = None
        self._watchdog_armed = False
        self._burst_t: list[int] = []
        self._burst_field: list[NDArray] = []
        self._burst_pwm: list[NDArray] = []
        self.watchdog_trips = 0
        self.records_written = 0  # records emitted in bursts (before any tampering)
        self.records_since_open = 0  # the same, since the host last opened the port
        # (tick in us since power-up, PWM counts) of each accepted packet, newest last
        self.accepted: deque[tuple[int, tuple[int, int, int, int]]] = deque(maxlen=100_000)

    @property
    def now_us(self) -> int:
        """Emulated time in us since power-up."""
        return self._loop.now_us

    @property
    def running(self) -> bool:
        """Whether the loop runs (the start-up wait is over)."""
        return self._loop.running

    @property
    def pwm(self) -> NDArray[np.int64]:
        """PWM counts in force, shape (4,), order x+, x-, y+, y-."""
        return self._pwm.copy()

    @property
    def parser(self) -> CommandParser:
        """The command parser (counts accepted and discarded packets)."""
        return self._parser

    def receive(self, data: bytes) -> None:
        """Queue bytes from the host; the loop parses them at its next tick."""
        self._input += data

    def port_opened(self) -> None:
        """Tell the board that the host opened the port: wait the start-up delay again.

        The clock keeps running (it counts since power-up) and a partly
        filled burst is discarded.
        """
        self._loop.suspend()
        self.records_since_open = 0
        self._burst_t.clear()
        self._burst_field.clear()
        self._burst_pwm.clear()

    def tamper_next_burst(self, edit: Callable[[bytes], bytes]) -> None:
        """Pass the next written burst through ``edit`` (fault injection for tests).

        Parameters
        ----------
        edit : callable
            Maps the burst's bytes to the bytes actually written.
        """
        self._loop.tampers.append(edit)

    def advance_to(self, t_us: int) -> bytes:
        """Run the loop up to time ``t_us`` (us since power-up).

        Parameters
        ----------
        t_us : int
            Target time; earlier than ``now_us`` does nothing.

        Returns
        -------
        bytes
            The bytes written by the board meanwhile (whole bursts).
        """
        loop = self._loop
        out = []
        while loop.next_tick_us <= t_us:
            tick = loop.next_tick_us
            self._tick(tick)
            if len(self._burst_t) == BURST_RECORDS:
                burst = pack_records(
                    np.array(self._burst_t, dtype=np.int64),
                    np.stack(self._burst_field),
                    np.stack(self._burst_pwm),
                )
                self.records_written += BURST_RECORDS
                self.records_since_open += BURST_RECORDS
                if loop.tampers:
                    burst = loop.tampers.popleft()(burst)
                out.append(burst)
                self._burst_t.clear()
                self._burst_field.clear()
                self._burst_pwm.clear()
            loop.next_tick_us = tick + SAMPLE_PERIOD_US
        loop.now_us = max(loop.now_us, int(t_us))
        return b''.join(out)

    def _tick(self, tick_us: int) -> None:
        if self._last_accept_us is None:
            self._last_accept_us = tick_us  # the watchdog counts from the loop start
        if self._input:
            packets = self._parser.feed(bytes(self._input))
            self._input.clear()
            self.accepted.extend((tick_us, packet) for packet in packets)
            if packets:
                self._pwm = np.clip(packets[-1], -PWM_FULL_SCALE, PWM_FULL_SCALE).astype(np.int64)
                self._last_accept_us = tick_us
                self._watchdog_armed = True
        if self._watchdog_armed and tick_us - self._last_accept_us > self._watchdog_us:
            self._pwm = np.zeros(4, dtype=np.int64)
            self._watchdog_armed = False
            self.watchdog_trips += 1
        field_mT = np.asarray(self.plant(self._pwm.copy(), tick_us * 1e-6), dtype=float)
        if field_mT.shape != (self.n_sensors, 3):
            raise ValueError(
                f'plant must return shape ({self.n_sensors}, 3), got {field_mT.shape}'
            )
        self._burst_t.append((self.clock_start_us + tick_us) % _CLOCK_WRAP)
        self._burst_field.append(field_mT)
        self._burst_pwm.append(self._pwm.copy())


class V4xFirmware:
    """Emulator of the V4x firmware's text telemetry (read-only for the host).

    Parameters
    ----------
    plant : callable
        ``plant(pwm_counts (4,), time_s) -> field_mT (n_sensors, 3)``; its
        PWM input is the coil current converted with ``scaling``.
    n_sensors : int
        Sensors reported per line (>= 1).
    current : callable, optional
        ``current(time_s) -> (4,)`` coil currents in A that the on-board
        controller applies (default: zero).
    scaling : CurrentScaling, optional
        Current to PWM-count conversion for the plant's input (default
        ``CurrentScaling.from_supply(12.0, 4.0)``).
    log_period : float, optional
        Seconds between telemetry lines (default 1 ms).
    startup_delay : float, optional
        Seconds before the start-up messages and the first line.

    Notes
    -----
    Start-up prints one ``Sensor on channel K initialized successfully.``
    per sensor, ``Calibrating sensors...``, then ``Sensor calibration
    complete.``; the field measured at calibration is the baseline that
    every reported field has subtracted (feedthrough removal beyond that
    baseline is not modelled). ``inject_freeze`` makes the board print
    ``Sensor freeze detected! Resetting...`` and ``I2C and sensor reset
    complete`` before the next line.
    """

    def __init__(
        self,
        plant: Plant,
        n_sensors: int = 1,
        *,
        current: Callable[[float], ArrayLike] | None = None,
        scaling: CurrentScaling | None = None,
        log_period: float = 1e-3,
        startup_delay: float = 2.0,
    ) -> None:
        if not callable(plant):
            raise TypeError(f'plant must be callable, got {type(plant).__name__}')
        if not isinstance(n_sensors, int) or n_sensors < 1:
            raise ValueError(f'n_sensors must be an int >= 1, got {n_sensors!r}')
        period = _check_delay('log_period', log_period)
        if period < 1:
            raise ValueError(f'log_period must be >= 1 us, got {log_period!r}')
        self.plant = plant
        self.n_sensors = n_sensors
        self.current = current if current is not None else (lambda t: np.zeros(4))
        self.scaling = scaling if scaling is not None else CurrentScaling.from_supply(12.0, 4.0)
        delay = _check_delay('startup_delay', startup_delay)
        self._loop = _Loop(next_tick_us=delay, startup_delay_us=delay, resume_us=delay)
        self._period_us = period
        self._baseline: NDArray | None = None
        self._pending_info: list[str] = []

    @property
    def now_us(self) -> int:
        """Emulated time in us since power-up."""
        return self._loop.now_us

    @property
    def running(self) -> bool:
        """Whether the loop runs (the start-up wait is over)."""
        return self._loop.running

    def receive(self, data: bytes) -> None:
        """Ignore host bytes (the V4x firmware reads nothing)."""

    def port_opened(self) -> None:
        """Tell the board that the host opened the port: wait, then recalibrate."""
        self._loop.suspend()
        self._baseline = None

    def inject_freeze(self) -> None:
        """Report a sensor freeze and reset before the next telemetry line."""
        self._pending_info += [
            'Sensor freeze detected! Resetting...',
            'I2C and sensor reset complete',
        ]

    def tamper_next_burst(self, edit: Callable[[bytes], bytes]) -> None:
        """Pass the next written line through ``edit`` (fault injection)."""
        self._loop.tampers.append(edit)

    def advance_to(self, t_us: int) -> bytes:
        """Run up to ``t_us`` (us since power-up); return the text written."""
        loop = self._loop
        out = []
        while loop.next_tick_us <= t_us:
            tick = loop.next_tick_us
            t_s = tick * 1e-6
            amps = np.asarray(self.current(t_s), dtype=float).reshape(4)
            field_mT = np.asarray(self.plant(self.scaling.to_counts(amps), t_s), dtype=float)
            if self._baseline is None:
                lines = [
                    f'Sensor on channel {k} initialized successfully.'
                    for k in range(self.n_sensors)
                ]
                lines += ['Calibrating sensors...', 'Sensor calibration complete.']
                out += [(line + '\r\n').encode('ascii') for line in lines]
                self._baseline = field_mT
            out += [(line + '\r\n').encode('ascii') for line in self._pending_info]
            self._pending_info.clear()
            line = format_telemetry_line(t_s, amps, field_mT - self._baseline)
            if loop.tampers:
                line = loop.tampers.popleft()(line)
            out.append(line)
            loop.next_tick_us = tick + self._period_us
        loop.now_us = max(loop.now_us, int(t_us))
        return b''.join(out)
