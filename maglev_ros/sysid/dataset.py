"""Input/output data sets for identification (the toolbox's ``iddata`` and ``idfilt``).

An :class:`IdData` holds ``N`` samples of ``ny`` outputs and ``nu`` inputs taken
every ``Ts`` seconds, with channel names and units.  It is immutable: slicing,
splitting, detrending, filtering and decimation all return new data sets.
Several experiments are combined with :func:`merge`; every estimator accepts
either one :class:`IdData` or a sequence of them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy import signal

__all__ = ['IdData', 'as_experiments', 'merge']


def _names(given: Sequence[str] | None, prefix: str, count: int, arg: str) -> tuple[str, ...]:
    if given is None:
        return tuple(f'{prefix}{i + 1}' for i in range(count))
    names = tuple(str(n) for n in given)
    if len(names) != count:
        raise ValueError(f'{arg} has {len(names)} entries, expected {count}: {names!r}')
    return names


def _as_columns(values: np.ndarray, arg: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.ndim == 1:
        array = array[:, None]
    if array.ndim != 2:
        raise ValueError(f'{arg} must be 1-D or 2-D (N, channels), got shape {array.shape}')
    # own copy, channel-major: each channel contiguous, returned as an (N, channels) view
    array = np.array(array.T, dtype=float, order='C').T
    if not np.all(np.isfinite(array)):
        bad = int(np.count_nonzero(~np.isfinite(array)))
        raise ValueError(f'{arg} contains {bad} NaN or infinite values')
    return array


@dataclass(frozen=True)
class IdData:
    """Sampled input/output data of one experiment.

    Parameters
    ----------
    y : array_like, shape (N, ny) or (N,)
        Measured outputs, one column per output channel (stored channel-major:
        ``y.T`` is C-contiguous, so each channel is one contiguous block).
    u : array_like, shape (N, nu) or (N,)
        Measured inputs, one column per input channel (``nu`` may be 0).
    Ts : float
        Sample time in seconds, > 0.
    output_names, input_names : sequence of str, optional
        Channel names (default ``y1, y2, ...`` and ``u1, u2, ...``).
    output_units, input_units : sequence of str, optional
        Channel units (default empty strings).
    t0 : float
        Time of the first sample in seconds (default 0; a slice such as the
        validation part of :meth:`split` keeps the record's time axis).

    Raises
    ------
    ValueError
        If the arrays disagree in length, contain NaN/inf, or ``Ts <= 0``.
    """

    y: np.ndarray
    u: np.ndarray
    Ts: float
    output_names: tuple[str, ...] = field(default=None)  # type: ignore[assignment]
    input_names: tuple[str, ...] = field(default=None)  # type: ignore[assignment]
    output_units: tuple[str, ...] = field(default=None)  # type: ignore[assignment]
    input_units: tuple[str, ...] = field(default=None)  # type: ignore[assignment]
    t0: float = 0.0

    def __post_init__(self) -> None:
        y = _as_columns(self.y, 'y')
        u = np.asarray(self.u, dtype=float)
        u = np.zeros((y.shape[0], 0)) if u.size == 0 and u.ndim <= 1 else _as_columns(u, 'u')
        if u.shape[0] != y.shape[0]:
            raise ValueError(f'u has {u.shape[0]} samples but y has {y.shape[0]}')
        Ts = float(self.Ts)
        if not np.isfinite(Ts) or Ts <= 0:
            raise ValueError(f'Ts must be a positive sample time in seconds, got {self.Ts!r}')
        y.setflags(write=False)
        u.setflags(write=False)
        ny, nu = y.shape[1], u.shape[1]
        object.__setattr__(self, 'y', y)
        object.__setattr__(self, 'u', u)
        object.__setattr__(self, 'Ts', Ts)
        object.__setattr__(
            self, 'output_names', _names(self.output_names, 'y', ny, 'output_names')
        )
        object.__setattr__(self, 'input_names', _names(self.input_names, 'u', nu, 'input_names'))
        units_y = ('',) * ny if self.output_units is None else self.output_units
        units_u = ('',) * nu if self.input_units is None else self.input_units
        object.__setattr__(self, 'output_units', _names(units_y, '', ny, 'output_units'))
        object.__setattr__(self, 'input_units', _names(units_u, '', nu, 'input_units'))

    # ------------------------------------------------------------------ basics
    @property
    def N(self) -> int:  # noqa: N802 - toolbox name
        """Number of samples."""
        return self.y.shape[0]

    @property
    def ny(self) -> int:
        """Number of output channels."""
        return self.y.shape[1]

    @property
    def nu(self) -> int:
        """Number of input channels."""
        return self.u.shape[1]

    @property
    def time(self) -> np.ndarray:
        """Sample instants in seconds, shape (N,), starting at ``t0``."""
        return self.t0 + np.arange(self.N) * self.Ts

    def __len__(self) -> int:
        return self.N

    def __getitem__(self, index: slice) -> IdData:
        """Return the samples selected by a slice (a step decimates without filtering)."""
        if not isinstance(index, slice):
            raise TypeError(f'IdData index must be a slice of samples, got {index!r}')
        step = 1 if index.step is None else int(index.step)
        if step <= 0:
            raise ValueError(f'slice step must be positive, got {index.step!r}')
        first = range(self.N)[index]
        t0 = self.t0 + (first[0] if len(first) else 0) * self.Ts
        return replace(self, y=self.y[index], u=self.u[index], Ts=self.Ts * step, t0=t0)

    def select(
        self, outputs: Sequence[int] | None = None, inputs: Sequence[int] | None = None
    ) -> IdData:
        """Keep only some channels (0-based indices), like ``data(:, outputs, inputs)``.

        Parameters
        ----------
        outputs, inputs : sequence of int, optional
            Channel indices to keep (default all).

        Returns
        -------
        IdData
            The reduced data set.
        """
        oy = list(range(self.ny)) if outputs is None else [int(i) for i in outputs]
        iu = list(range(self.nu)) if inputs is None else [int(i) for i in inputs]
        for name, idx, count in (('outputs', oy, self.ny), ('inputs', iu, self.nu)):
            if any(i < 0 or i >= count for i in idx):
                raise ValueError(f'{name} indices {idx} out of range 0..{count - 1}')
        return IdData(
            self.y[:, oy],
            self.u[:, iu],
            self.Ts,
            [self.output_names[i] for i in oy],
            [self.input_names[i] for i in iu],
            [self.output_units[i] for i in oy],
            [self.input_units[i] for i in iu],
            self.t0,
        )

    def split(self, at: float | int = 0.5) -> tuple[IdData, IdData]:
        """Split into estimation and validation data.

        Parameters
        ----------
        at : int or float
            A sample index ``0 < at < N`` (int) or a fraction ``0 < at < 1``
            (float) of the samples going to the estimation part.

        Returns
        -------
        tuple of IdData
            ``(estimation, validation)``: samples ``[:n]`` and ``[n:]``.
        """
        if isinstance(at, (int, np.integer)) and not isinstance(at, bool):
            n = int(at)
        else:
            frac = float(at)
            if not 0.0 < frac < 1.0:
                raise ValueError(f'split fraction must be in (0, 1), got {at!r}')
            n = int(round(frac * self.N))
        if not 0 < n < self.N:
            raise ValueError(f'split index must be in 1..{self.N - 1}, got {at!r}')
        return self[:n], self[n:]

    # ---------------------------------------------------------- preprocessing
    def detrend(self, kind: str = 'constant') -> IdData:
        """Remove the mean (``'constant'``) or a straight line (``'linear'``) from each channel.

        Parameters
        ----------
        kind : {'constant', 'linear'}
            The toolbox's ``detrend(data, 0)`` and ``detrend(data, 1)``.

        Returns
        -------
        IdData
            Detrended copy.
        """
        if kind not in ('constant', 'linear'):
            raise ValueError(f"detrend kind must be 'constant' or 'linear', got {kind!r}")
        y = signal.detrend(self.y, axis=0, type=kind)
        u = signal.detrend(self.u, axis=0, type=kind) if self.nu else self.u
        return replace(self, y=y, u=u)

    def filter(
        self, band: tuple[float, float], order: int = 5, zero_phase: bool = False
    ) -> IdData:
        """Butterworth-filter all channels, like the toolbox's ``idfilt(data, order, band)``.

        Parameters
        ----------
        band : (float, float)
            Pass band ``(low, high)`` in Hz.  ``low = 0`` gives a low-pass filter,
            ``high >= Nyquist`` (or ``inf``) a high-pass filter.
        order : int
            Butterworth order (per band edge), >= 1.
        zero_phase : bool
            Filter forwards and backwards (``filtfilt``), as ``idfilt`` with the
            ``'noncausal'`` option; the default is causal filtering.

        Returns
        -------
        IdData
            Filtered copy.
        """
        low, high = (float(b) for b in band)
        nyq = 0.5 / self.Ts
        if order < 1:
            raise ValueError(f'filter order must be >= 1, got {order!r}')
        if low < 0 or high <= low:
            raise ValueError(f'filter band must satisfy 0 <= low < high (Hz), got {band!r}')
        has_low, has_high = low > 0, high < nyq
        if not has_low and not has_high:
            return self
        if has_low and low >= nyq:
            raise ValueError(f'filter band low edge {low} Hz is above Nyquist {nyq} Hz')
        if has_low and has_high:
            sos = signal.butter(order, [low, high], 'bandpass', fs=1.0 / self.Ts, output='sos')
        elif has_low:
            sos = signal.butter(order, low, 'highpass', fs=1.0 / self.Ts, output='sos')
        else:
            sos = signal.butter(order, high, 'lowpass', fs=1.0 / self.Ts, output='sos')
        run = signal.sosfiltfilt if zero_phase else signal.sosfilt
        u = run(sos, self.u, axis=0) if self.nu else self.u
        return replace(self, y=run(sos, self.y, axis=0), u=u)

    def decimate(self, q: int) -> IdData:
        """Low-pass filter (zero phase, Chebyshev) and keep every ``q``-th sample.

        Parameters
        ----------
        q : int
            Decimation factor >= 1; the new sample time is ``q * Ts``.

        Returns
        -------
        IdData
            Decimated copy.
        """
        q = int(q)
        if q < 1:
            raise ValueError(f'decimation factor q must be >= 1, got {q!r}')
        if q == 1:
            return self
        y = signal.decimate(self.y, q, axis=0, zero_phase=True)
        u = signal.decimate(self.u, q, axis=0, zero_phase=True) if self.nu else self.u[::q]
        return replace(self, y=y, u=u, Ts=self.Ts * q)

    def __repr__(self) -> str:
        return (
            f'IdData(N={self.N}, ny={self.ny}, nu={self.nu}, Ts={self.Ts:g} s, '
            f'outputs={list(self.output_names)}, inputs={list(self.input_names)})'
        )


def merge(*experiments: IdData) -> tuple[IdData, ...]:
    """Combine experiments with the same channels into a multi-experiment set.

    Parameters
    ----------
    *experiments : IdData
        Data sets with equal ``ny``, ``nu`` and ``Ts``.

    Returns
    -------
    tuple of IdData
        The experiments, checked for consistency; every estimator accepts it.
    """
    if not experiments:
        raise ValueError('merge needs at least one IdData')
    first = experiments[0]
    for i, data in enumerate(experiments):
        if not isinstance(data, IdData):
            raise TypeError(f'experiment {i} is {type(data).__name__}, expected IdData')
        if (data.ny, data.nu) != (first.ny, first.nu):
            raise ValueError(
                f'experiment {i} has ny={data.ny}, nu={data.nu}; '
                f'expected ny={first.ny}, nu={first.nu}'
            )
        if not np.isclose(data.Ts, first.Ts):
            raise ValueError(f'experiment {i} has Ts={data.Ts}, expected {first.Ts}')
    return tuple(experiments)


def as_experiments(data: IdData | Sequence[IdData]) -> tuple[IdData, ...]:
    """Return ``data`` as a non-empty tuple of consistent experiments.

    Parameters
    ----------
    data : IdData or sequence of IdData
        One experiment or several (see :func:`merge`).

    Returns
    -------
    tuple of IdData
        The experiments.
    """
    if isinstance(data, IdData):
        return (data,)
    if isinstance(data, (list, tuple)):
        return merge(*data)
    raise TypeError(f'data must be IdData or a sequence of IdData, got {type(data).__name__}')
