"""V4x text telemetry: line parser, stream splitter and line formatter.

A telemetry line (CR LF terminated) is a comma-separated list of
``key:value`` pairs in a fixed order::

    time:12.345678,Ix_plus:0.123456,Ix_minus:-0.123456,Iy_plus:0.000000,
    Iy_minus:0.000000,bx0:0.512000,by0:-0.030000,bz0:41.200000,bx1:...

(one line; time in s since boot, currents in A, fields in mT after the
board's baseline and feedthrough removal). Any other line is an
informational message (``Calibrating sensors...``, ``Sensor freeze
detected! Resetting...``); it is passed on as an ``InfoMessage`` with a
severity. A line that looks like telemetry (it has ``key:number`` pairs)
but does not parse completely, e.g. the tail of a line the host started
reading in the middle, is counted as malformed and dropped.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from enum import IntEnum

import numpy as np
from numpy.typing import NDArray

__all__ = [
    'CURRENT_KEYS',
    'InfoMessage',
    'Severity',
    'TelemetryError',
    'TelemetrySample',
    'TelemetryStats',
    'TelemetryStream',
    'format_telemetry_line',
    'parse_telemetry_line',
]

CURRENT_KEYS = ('Ix_plus', 'Ix_minus', 'Iy_plus', 'Iy_minus')  # order x+, x-, y+, y-
_FIELD_AXES = ('bx', 'by', 'bz')
_PAIR = re.compile(r'[A-Za-z_]+[0-9]*:[-+]?(\d|\.\d|nan|inf)', re.IGNORECASE)
MAX_LINE_BYTES = 4096  # a longer line is not telemetry: dropped as garbage


class TelemetryError(ValueError):
    """A telemetry line does not have the expected keys or values."""


class Severity(IntEnum):
    """Severity of an informational line (values as diagnostic_msgs levels)."""

    INFO = 0
    WARN = 1
    ERROR = 2


@dataclass(frozen=True)
class TelemetrySample:
    """One parsed telemetry line.

    Attributes
    ----------
    time : float
        Board time in seconds since boot.
    current : ndarray of float64, shape (4,)
        Measured coil currents in ampere, order x+, x-, y+, y-.
    field_mT : ndarray of float64, shape (n_sensors, 3)
        Fields in millitesla after the board's baseline and feedthrough removal.
    """

    time: float
    current: NDArray[np.float64]
    field_mT: NDArray[np.float64]  # noqa: N815 (unit symbol mT)


@dataclass(frozen=True)
class InfoMessage:
    """An informational line from the board.

    Attributes
    ----------
    text : str
        The line without its line end.
    severity : Severity
        WARN for fault reports (freeze, reset, fail, error), else INFO.
    """

    text: str
    severity: Severity


_WARN_WORDS = ('freeze', 'fail', 'error', 'timeout', 'not found', 'resetting')


def _classify(text: str) -> Severity:
    lower = text.lower()
    return Severity.WARN if any(word in lower for word in _WARN_WORDS) else Severity.INFO


def parse_telemetry_line(line: str, n_sensors: int | None = None) -> TelemetrySample:
    """Parse one telemetry line.

    Parameters
    ----------
    line : str
        The line, with or without its CR LF.
    n_sensors : int, optional
        Expected number of sensors; inferred from the line if None.

    Returns
    -------
    TelemetrySample
        The parsed sample.

    Raises
    ------
    TelemetryError
        If keys are missing, out of order or unknown, a value is not a finite
        number, or the number of sensors differs from ``n_sensors``.
    """
    pairs = line.strip().split(',')
    keys = []
    values = []
    for pair in pairs:
        key, sep, text = pair.partition(':')
        if not sep:
            raise TelemetryError(f'line has an item without ":": {pair!r}')
        try:
            value = float(text)
        except ValueError:
            raise TelemetryError(f'{key} must be a number, got {text!r}') from None
        if not math.isfinite(value):
            raise TelemetryError(f'{key} must be finite, got {text!r}')
        keys.append(key)
        values.append(value)
    n_fields = len(keys) - 1 - len(CURRENT_KEYS)
    if n_fields <= 0 or n_fields % 3:
        raise TelemetryError(
            f'line must have time, 4 currents and 3 fields per sensor, got {keys}'
        )
    found = n_fields // 3
    if n_sensors is not None and found != n_sensors:
        raise TelemetryError(f'line must have {n_sensors} sensors, got {found}')
    expected = ['time', *CURRENT_KEYS]
    expected += [f'{axis}{k}' for k in range(found) for axis in _FIELD_AXES]
    if keys != expected:
        raise TelemetryError(f'line keys must be {expected}, got {keys}')
    return TelemetrySample(
        values[0],
        np.array(values[1:5]),
        np.array(values[5:]).reshape(found, 3),
    )


def format_telemetry_line(time: float, current: NDArray, field_mT: NDArray) -> bytes:
    """Format a telemetry line as the V4x firmware prints it.

    Parameters
    ----------
    time : float
        Board time in s.
    current : array_like, shape (4,)
        Coil currents in A, order x+, x-, y+, y-.
    field_mT : array_like, shape (n_sensors, 3)
        Fields in mT.

    Returns
    -------
    bytes
        The ASCII line with 6 decimals per value, ending in CR LF.
    """
    amps = np.asarray(current, dtype=float).reshape(4)
    field = np.asarray(field_mT, dtype=float).reshape(-1, 3)
    items = [f'time:{time:.6f}']
    items += [f'{key}:{value:.6f}' for key, value in zip(CURRENT_KEYS, amps, strict=True)]
    for k, row in enumerate(field):
        items += [f'{axis}{k}:{value:.6f}' for axis, value in zip(_FIELD_AXES, row, strict=True)]
    return (','.join(items) + '\r\n').encode('ascii')


@dataclass(frozen=True)
class TelemetryStats:
    """Counters of a ``TelemetryStream``.

    Attributes
    ----------
    samples : int
        Telemetry lines parsed.
    messages : int
        Informational lines passed on.
    malformed : int
        Lines that looked like telemetry but did not parse.
    dropped_bytes : int
        Bytes of malformed and over-long lines.
    """

    samples: int
    messages: int
    malformed: int
    dropped_bytes: int


class TelemetryStream:
    """Split the V4x byte stream into samples and informational messages.

    Parameters
    ----------
    n_sensors : int, optional
        Expected number of sensors; lines with another count are malformed.
        If None, every line must match the count of the first sample.
    """

    def __init__(self, n_sensors: int | None = None) -> None:
        if n_sensors is not None and (not isinstance(n_sensors, int) or n_sensors < 1):
            raise ValueError(f'n_sensors must be a positive int or None, got {n_sensors!r}')
        self.n_sensors = n_sensors
        self._partial = b''
        self._overlong = False
        self._samples = 0
        self._messages = 0
        self._malformed = 0
        self._dropped = 0

    @property
    def stats(self) -> TelemetryStats:
        """Snapshot of the counters."""
        return TelemetryStats(self._samples, self._messages, self._malformed, self._dropped)

    def feed(self, data: bytes) -> list[TelemetrySample | InfoMessage]:
        """Parse the next chunk of the stream.

        Parameters
        ----------
        data : bytes
            Bytes as read from the serial port, any length.

        Returns
        -------
        list of TelemetrySample or InfoMessage
            The complete lines in this chunk, in order; empty lines are
            skipped.
        """
        lines = (self._partial + data).split(b'\n')
        self._partial = lines.pop()
        out: list[TelemetrySample | InfoMessage] = []
        for raw in lines:
            if self._overlong:  # the rest of a line that was already dropped
                self._overlong = False
                self._dropped += len(raw) + 1
                continue
            item = self._parse(raw)
            if item is not None:
                out.append(item)
        if len(self._partial) > MAX_LINE_BYTES:
            self._dropped += len(self._partial)
            self._malformed += not self._overlong
            self._partial = b''
            self._overlong = True
        return out

    def _parse(self, raw: bytes) -> TelemetrySample | InfoMessage | None:
        text = raw.decode('ascii', errors='replace').strip()
        if not text:
            return None
        if text.startswith('time:'):
            try:
                sample = parse_telemetry_line(text, self.n_sensors)
            except TelemetryError:
                pass
            else:
                if self.n_sensors is None:
                    self.n_sensors = sample.field_mT.shape[0]
                self._samples += 1
                return sample
        elif not _PAIR.search(text):
            self._messages += 1
            return InfoMessage(text, _classify(text))
        self._malformed += 1
        self._dropped += len(raw) + 1
        return None
