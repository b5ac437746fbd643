"""Byte-exact emulator of the V4x PC-control firmware (ROS-free, no I/O).

Same contract as the emulators of :mod:`.firmware`: ``advance_to(t_us)`` runs
the board up to ``t_us`` (us since power-up) and returns the bytes it wrote;
``receive(data)`` hands over host bytes. The plant is stepped every 200 us
whatever the firmware does (physics time never stops); the firmware's own
work follows the published sketch:

* **Set-up** (``setup_us``, about 3.8 s; requests wait and are answered when
  it ends): after ``init_delay`` s of bus and sensor set-up, the *baseline*
  is the mean of 1000 readings 1 ms apart; then the *feedthrough* of each
  coil (x+, x-, y+, y-) into the sensor's x (x coils) or y axis (y coils)
  at PWM 50, 100, 150: 50 ms settle, ten readings 10 ms apart of the field and
  the coil's current (ADC), coil off, 50 ms pause; the slope is
  ``(mean field - baseline) / mean current``, negated for x+ and y+, averaged
  over the three levels. The readings come from ``setup_plant`` when given
  (the board powered up without the levitating magnet: the default of the
  virtual board), else from ``plant``; the plant itself is then started
  when the loop starts (the magnet is put in place after set-up), or
  ``place_after`` s after set-up (the readings come from ``setup_plant``
  until then: the host may measure the board without the magnet first).
* **Sample** (every 200 us): the four currents through the 10-bit ADC
  (``I = (adc * 3.3 / 1023 - 1.65) / 0.5``), the field of one sensor minus
  the baseline plus the feedthrough compensation, x and y low-pass filtered
  (``f = 0.2 raw + 0.8 f``), z not; ``dB = 0.05 (f - f_prev) / dt + 0.95 dB``
  for x and y, dBz = 0. Values are stored as float32 at every assignment.
* **Freeze check**: a reading identical to the previous one (all three axes)
  20 times in a row resets the sensor: 160 ms without samples or replies.
* **Serial**: ``readBytesUntil(0x00, buffer, 64)``: up to 63 bytes per frame
  (the rest is the next frame); while no ``0x00`` came, the loop blocks,
  up to 1 s after each byte, then decodes the partial frame anyway. The
  firmware's decoder (reproduced, not the ``cobs`` package: it adds a zero
  after the last block and reads past the frame when a code byte points
  beyond it, into the bytes the buffer held before) feeds the dispatch of
  ``command[0]``: 01 .. 05, AA, else the error reply ``00 67``. A lone
  ``0x00`` gets no reply. The buffers keep the bytes of earlier frames, as
  the stack buffers of the firmware do in practice (undefined in C: counted
  in ``overreads``).
* **No watchdog**: the PWM stays until ``03`` or ``04``.
"""

from __future__ import annotations

import struct
from collections import Counter, deque
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from . import v4x_pc_protocol as proto
from .cobs_frame import encode_frame
from .firmware import Plant
from .scaling import V4X_PWM_FULL_SCALE, CurrentScaling

__all__ = ['FREEZE_LIMIT', 'SETUP_US', 'V4xPcFirmware', 'adc_current']

SAMPLE_US = 200  # us: the sketch's sampling interval (5 kHz)
FREEZE_LIMIT = 20  # identical readings in a row before the sensor reset
FREEZE_RESET_US = 160_000  # us without samples during the sensor reset
READ_TIMEOUT_US = 1_000_000  # us: Stream timeout per byte of readBytesUntil
BUFFER = 64  # bytes of the firmware's frame buffer (63 usable)
# the sketch's constexpr floats, widened to double in its expressions
_ALPHA, _DALPHA = float(np.float32(0.20)), float(np.float32(0.05))
_BASELINE_READS, _BASELINE_STEP_US = 1000, 1000
_LEVELS = (50, 100, 150)
_SETTLE_US, _SEGMENT_US, _READ_STEP_US, _PAUSE_US = 50_000, 100_000, 10_000, 50_000
_LEVEL_US = _SETTLE_US + _SEGMENT_US + _PAUSE_US
# calibration order of the sketch: (coil index x+ x- y+ y-, axis, negate slope)
_CHANNELS = ((0, 0, True), (1, 0, False), (2, 1, True), (3, 1, False))
SETUP_US = 400_000 + _BASELINE_READS * _BASELINE_STEP_US + len(_CHANNELS) * 3 * _LEVEL_US


_F32 = struct.Struct('<f')
_F32x3 = struct.Struct('<3f')


def _f32(value: float) -> float:
    """Round a double to the nearest float32 (a C ``float`` assignment)."""
    return _F32.unpack(_F32.pack(value))[0]


def _f32_list(values: list[float]) -> tuple[float, float, float]:
    return _F32x3.unpack(_F32x3.pack(*values))


def adc_current(current_A: NDArray) -> NDArray[np.float32]:  # noqa: N803
    """Coil currents as the board's shunt amplifier and 10-bit ADC report them.

    Parameters
    ----------
    current_A : ndarray, shape (4,)
        True currents, A.

    Returns
    -------
    ndarray of float32, shape (4,)
        ``(adc * 3.3 / 1023 - 1.65) / 0.5`` with ``adc`` the rounded, clipped
        reading of ``1.65 + 0.5 I`` volts (range about +-3.3 A).
    """
    volts = 1.65 + 0.5 * np.asarray(current_A, dtype=float)
    adc = np.clip(np.rint(volts * 1023 / 3.3), 0, 1023)
    voltage = np.float32(adc * 3.3 / 1023)  # float voltage = (data * 3.3) / 1023
    diff = np.float32(voltage.astype(float) - 1.65)
    return np.float32(diff.astype(float) / 0.5)


class V4xPcFirmware:
    """Emulator of the V4x PC-control firmware (module docstring).

    Parameters
    ----------
    plant : callable
        ``plant(pwm_counts (4,), time_s) -> field_mT (n_sensors, 3)``, PWM in
        8-bit counts, order x+, x-, y+, y-.
    scaling : CurrentScaling, optional
        PWM to coil current (for the ADC readings; default: the plant's
        ``scaling`` attribute, else 12 V / 4 ohm at 255 counts).
    setup_plant : callable, optional
        The field source during set-up (the board without the levitating
        magnet); default: ``plant``.
    sensor : int, optional
        Which of the plant's sensors the board reads (mux channel 7).
    init_delay : float, optional
        s of bus and sensor set-up before the baseline.
    place_after : float, optional
        s after set-up at which the levitating magnet is put in place (the
        readings come from ``setup_plant`` until then; default 0: at the end
        of set-up). Needs ``setup_plant``.
    freeze_limit : int, optional
        Identical readings in a row that reset the sensor.
    """

    #: s between a pacing layer's wake-ups (one sample period: a request finds the
    #: board caught up, as the firmware is between its samples)
    pacing_period = SAMPLE_US * 1e-6
    #: a pacing layer runs the samples up to a request's arrival before handing it over
    answers_on_arrival = True

    def __init__(
        self,
        plant: Plant,
        *,
        scaling: CurrentScaling | None = None,
        setup_plant: Plant | None = None,
        sensor: int = 0,
        init_delay: float = 0.4,
        freeze_limit: int = FREEZE_LIMIT,
        place_after: float = 0.0,
    ) -> None:
        if not callable(plant) or (setup_plant is not None and not callable(setup_plant)):
            raise TypeError('plant and setup_plant must be callable')
        if not init_delay >= 0:
            raise ValueError(f'init_delay must be >= 0 s, got {init_delay!r}')
        if not place_after >= 0 or (place_after > 0 and setup_plant is None):
            raise ValueError(
                f'place_after must be >= 0 s (and > 0 needs a setup_plant), got {place_after!r}'
            )
        if freeze_limit < 1:
            raise ValueError(f'freeze_limit must be >= 1, got {freeze_limit}')
        self.plant = plant
        self.setup_plant = setup_plant
        self.scaling = scaling or getattr(plant, 'scaling', None)
        if self.scaling is None:
            self.scaling = CurrentScaling.from_supply(12.0, 4.0, V4X_PWM_FULL_SCALE)
        self.sensor = int(sensor)
        self.freeze_limit = int(freeze_limit)
        self._init_us = round(init_delay * 1e6)
        self.setup_us = self._init_us + SETUP_US - 400_000
        #: us since power-up at which the levitating magnet is in place
        self.placed_us = self.setup_us + round(place_after * 1e6)
        self.now_us = 0
        self._next_tick = 0
        self._pwm = np.zeros(4, dtype=np.int64)  # x+, x-, y+, y-
        self._adc_key: tuple | None = None
        self._adc = np.zeros(4, dtype=np.float32)
        self._adc_floats = [0.0] * 4
        self._input = bytearray()
        self._last_byte_us = 0
        self._blocked = False  # readBytesUntil waits for the rest of a frame
        self._resume_us = 0  # no samples or replies before this (sensor reset)
        self._rx = bytearray(BUFFER)  # the frame buffer, stale bytes kept
        self._cmd = bytearray(BUFFER)  # the decoded command buffer, stale bytes kept
        self._tampers: deque[Callable[[bytes], bytes]] = deque()
        # set-up accumulators
        self._baseline_sum = np.zeros(3)
        self.baseline_mT = np.zeros(3, dtype=np.float32)
        self.slopes = np.full(4, 0.5, dtype=np.float32)  # the sketch's defaults
        self._cal = {}  # (channel, level) -> [sum field, sum current, count]
        # loop state: Python floats holding float32 values, like the sketch's floats
        self._field = (0.0, 0.0, 0.0)  # filtered Bx, By, Bz
        self._rate = (0.0, 0.0, 0.0)  # dBx, dBy, dBz (stays 0)
        self._slopes_floats = self.slopes.astype(float).tolist()
        self._baseline_floats = [0.0] * 3
        self._prev_sample_us: int | None = None
        self._last_raw: NDArray | None = None
        self._freeze_count = 0
        # counters for hosts and tests
        self.requests: Counter[int] = Counter()  # command[0] -> count (0x100: lone 0x00)
        self.errors_sent = 0
        self.half_frames = 0  # frames executed after the 1 s timeout
        self.split_frames = 0  # frames cut at 63 bytes
        self.overreads = 0  # decodes that read past the frame
        self.freeze_resets = 0
        self.samples = 0
        self.applied: deque[tuple[int, int, int]] = deque(maxlen=100_000)  # (us, p_x, p_y)
        self.replies: deque[bytes] = deque(maxlen=100_000)  # payloads sent, newest last

    # -- host side -------------------------------------------------------------------------

    def power_up(self) -> V4xPcFirmware:
        """Run the set-up now, on emulated time: a board powered before its port opens.

        Baseline and feedthrough calibration take :attr:`setup_us` of the
        board's time (3.4 s and ``init_delay``); here they take the time the
        machine needs to compute them (about 50 ms). A
        :class:`~maglev_ros.hardware.virtual_board.VirtualBoard` given this
        firmware goes on from its clock.

        Returns
        -------
        V4xPcFirmware
            This firmware, set up (:attr:`running`).
        """
        self.advance_to(self.setup_us)
        return self

    @property
    def running(self) -> bool:
        """Whether set-up is over."""
        return self.now_us >= self.setup_us

    @property
    def pwm(self) -> NDArray[np.int64]:
        """PWM applied to x+, x-, y+, y- (8-bit counts; the pairs are antisymmetric)."""
        return self._pwm.copy()

    def receive(self, data: bytes) -> None:
        """Queue host bytes (read by the loop when it gets to them).

        Parameters
        ----------
        data : bytes
            Bytes from the host.
        """
        if data:
            self._input += data
            self._last_byte_us = self.now_us

    def port_opened(self) -> None:
        """Do nothing: opening the USB port does not reset a Teensy."""

    def tamper_next_burst(self, edit: Callable[[bytes], bytes]) -> None:
        """Pass the next output through ``edit`` (fault injection).

        Parameters
        ----------
        edit : callable
            ``edit(bytes) -> bytes``: what the host receives instead.
        """
        self._tampers.append(edit)

    def advance_to(self, t_us: int) -> bytes:
        """Run the board up to ``t_us``; return the bytes written meanwhile.

        Parameters
        ----------
        t_us : int
            Time since power-up, us (earlier than ``now_us``: nothing happens).
        """
        out: list[bytes] = []
        while self._next_tick <= t_us:
            tick = self._next_tick
            self._serve(tick, out)  # requests that arrived before this tick
            self._tick(tick)
            self._next_tick = tick + SAMPLE_US
        self.now_us = max(self.now_us, int(t_us))
        self._serve(self.now_us, out)
        data = b''.join(out)
        if data and self._tampers:
            data = self._tampers.popleft()(data)
        return data

    # -- loop ------------------------------------------------------------------------------

    def _tick(self, tick: int) -> None:
        if tick < self.setup_us:
            self._setup_tick(tick)
            return
        placed = tick >= self.placed_us
        field = self._read_plant(self.plant if placed else self.setup_plant, tick)
        if self._blocked or tick < self._resume_us:
            return  # the loop is stuck in readBytesUntil or in the sensor reset
        self._sample(tick, field)
        self._freeze_check(tick, field)

    def _read_plant(self, plant: Plant, tick: int) -> NDArray[np.float64]:
        fields = np.asarray(plant(self._pwm.copy(), tick * 1e-6), dtype=float)
        return fields.reshape(-1, 3)[self.sensor]

    def _currents(self) -> NDArray[np.float32]:
        key = tuple(self._pwm.tolist())
        if key != self._adc_key:  # the ADC reading follows the PWM (steady state)
            self._adc_key = key
            self._adc = adc_current(self.scaling.to_current(self._pwm))
            self._adc_floats = self._adc.astype(float).tolist()
        return self._adc

    def _setup_tick(self, tick: int) -> None:
        source = self.setup_plant if self.setup_plant is not None else self.plant
        t = tick - self._init_us
        base_end = _BASELINE_READS * _BASELINE_STEP_US
        if t < 0:
            source(self._pwm.copy(), tick * 1e-6)
            return
        if t < base_end:
            field = self._read_plant(source, tick)
            if t % _BASELINE_STEP_US == 0:
                # meanMagField += temp / 1000.0 (float += double, stored as float)
                self._baseline_sum = np.float32(
                    self._baseline_sum + np.float32(field).astype(float) / 1000.0
                )
            if t + SAMPLE_US >= base_end:
                self.baseline_mT = np.asarray(self._baseline_sum, dtype=np.float32)
                self._baseline_floats = self.baseline_mT.astype(float).tolist()
            return
        t -= base_end
        channel, rest = divmod(t, 3 * _LEVEL_US)
        level_index, in_level = divmod(rest, _LEVEL_US)
        coil, axis, negate = _CHANNELS[channel]
        on = in_level < _SETTLE_US + _SEGMENT_US
        self._pwm[:] = 0
        if on:
            self._pwm[coil] = _LEVELS[level_index]
        field = self._read_plant(source, tick)
        if _SETTLE_US <= in_level < _SETTLE_US + _SEGMENT_US and (
            (in_level - _SETTLE_US) % _READ_STEP_US == 0
        ):
            acc = self._cal.setdefault((channel, level_index), [0.0, 0.0, 0])
            acc[0] = _f32(acc[0] + _f32(float(field[axis])))  # float sums
            acc[1] = _f32(acc[1] + float(self._currents()[coil]))
            acc[2] += 1
        if in_level + SAMPLE_US >= _LEVEL_US and level_index == 2:
            total = 0.0
            for k in range(3):
                s_field, s_current, n = self._cal[(channel, k)]
                mean_field, mean_current = _f32(s_field / n), _f32(s_current / n)
                slope = _f32(_f32(mean_field - float(self.baseline_mT[axis])) / mean_current)
                total = _f32(total + (-slope if negate else slope))
            self.slopes[coil] = np.float32(_f32(total / 3))
            self._slopes_floats = self.slopes.astype(float).tolist()
        if tick + SAMPLE_US >= self.setup_us:
            self._pwm[:] = 0

    def _sample(self, tick: int, raw: NDArray[np.float64]) -> None:
        # float arithmetic as the sketch does it: double expressions, float storage
        dt = 0 if self._prev_sample_us is None else tick - self._prev_sample_us
        self._prev_sample_us = tick
        self._currents()
        i = self._adc_floats
        s = self._slopes_floats
        b = self._baseline_floats
        r = _f32_list(raw.tolist())
        # float expressions round at every operation (single-precision FPU)
        x = _f32(_f32(_f32(r[0] - b[0]) + _f32(s[0] * i[0])) - _f32(s[1] * i[1]))
        y = _f32(_f32(_f32(r[1] - b[1]) + _f32(s[2] * i[2])) - _f32(s[3] * i[3]))
        z = _f32(r[2] - b[2])
        px, py, _ = self._field
        # ALPHA * x is float; (1.0 - ALPHA) is double, so the sum is double
        fx = _f32(_f32(_ALPHA * x) + (1.0 - _ALPHA) * px)
        fy = _f32(_f32(_ALPHA * y) + (1.0 - _ALPHA) * py)
        if dt > 0:
            rx, ry, _ = self._rate
            fdt = _f32(float(dt))
            self._rate = (
                _f32(_DALPHA * (_f32(_f32(fx - px) / fdt) * 1e6) + (1.0 - _DALPHA) * rx),
                _f32(_DALPHA * (_f32(_f32(fy - py) / fdt) * 1e6) + (1.0 - _DALPHA) * ry),
                0.0,
            )
        self._field = (fx, fy, z)
        self.samples += 1

    @property
    def field_mT(self) -> NDArray[np.float32]:  # noqa: N802 (unit symbol mT)
        """Filtered Bx, By and unfiltered Bz (mT) of the latest sample, float32 (3,)."""
        return np.array(self._field, dtype=np.float32)

    @property
    def rate_mT_s(self) -> NDArray[np.float32]:  # noqa: N802 (unit symbol mT)
        """dBx, dBy (mT/s) of the latest sample and dBz (always 0), float32 (3,)."""
        return np.array(self._rate, dtype=np.float32)

    def _freeze_check(self, tick: int, raw: NDArray[np.float64]) -> None:
        reading = np.asarray(raw, dtype=np.float32)
        if self._last_raw is not None and np.array_equal(reading, self._last_raw):
            self._freeze_count += 1
        else:
            self._freeze_count = 0
        if self._freeze_count >= self.freeze_limit:
            self.freeze_resets += 1
            self._freeze_count = 0
            self._resume_us = tick + FREEZE_RESET_US
        self._last_raw = reading

    # -- serial ----------------------------------------------------------------------------

    def _serve(self, now: int, out: list[bytes]) -> None:
        """Take the frames the loop reads by ``now`` and answer them."""
        if now < self.setup_us or now < self._resume_us:
            return
        while self._input:
            data = self._input
            end = data.find(0, 0, BUFFER - 1)
            if end >= 0:  # a whole frame (possibly empty: no reply)
                frame = bytes(data[:end])
                del data[: end + 1]
                self._blocked = False
                if frame:
                    self._execute(frame, out)
                else:
                    self.requests[0x100] += 1
                continue
            if len(data) >= BUFFER - 1:  # 63 bytes and no terminator: cut here
                frame = bytes(data[: BUFFER - 1])
                del data[: BUFFER - 1]
                self.split_frames += 1
                self._blocked = False
                self._execute(frame, out)
                continue
            deadline = self._last_byte_us + READ_TIMEOUT_US
            if now < deadline:
                self._blocked = True  # wait for the rest (no samples meanwhile)
                return
            frame = bytes(data)
            data.clear()
            self._blocked = False
            self.half_frames += 1
            self._execute(frame, out)

    def _decode(self, frame: bytes) -> bytes:
        """Decode as the firmware does, over its stale buffers; return ``command``."""
        rx, cmd = self._rx, self._cmd
        n = len(frame)
        rx[:n] = frame
        rx[n] = 0  # readBytesUntil terminates the string
        src = dst = 0
        overread = False
        while src < n:
            code = rx[src] if src < BUFFER else 0
            src += 1
            for _ in range(1, code):
                if src >= n:
                    overread = True
                if dst < BUFFER:
                    cmd[dst] = rx[src] if src < BUFFER else 0
                dst += 1
                src += 1
            if code < 0xFF:
                if dst < BUFFER:
                    cmd[dst] = 0
                dst += 1
        self.overreads += overread
        return bytes(cmd)

    def _execute(self, frame: bytes, out: list[bytes]) -> None:
        command = self._decode(frame)
        code = command[0]
        self.requests[code] += 1
        if code == proto.READ_SENSORS:
            payload = proto.sensors_payload(self.field_mT, self.rate_mT_s)
        elif code == proto.READ_CURRENTS:
            payload = proto.currents_payload(self._currents())
        elif code == proto.SET_PWM:
            p_x = command[1] - command[3]  # x+ minus x- (wire order x+ y- x- y+)
            p_y = command[4] - command[2]  # y+ minus y-
            self._pwm[:] = (p_x, -p_x, p_y, -p_y)
            self.applied.append((self.now_us, p_x, p_y))
            payload = bytes([proto.SET_PWM])
        elif code == proto.RESET:
            self._pwm[:] = 0
            self.applied.append((self.now_us, 0, 0))
            payload = bytes([proto.RESET])
        elif code == proto.STATUS:
            payload = proto.status_payload(self.now_us // 1_000_000)
        elif code == proto.PING:
            out.append(bytes([proto.PING_REPLY]))
            return
        else:
            self.errors_sent += 1
            payload = proto.error_payload()
        self.replies.append(payload)
        out.append(encode_frame(payload))
