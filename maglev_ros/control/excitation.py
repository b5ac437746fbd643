"""The excitation the controller adds to its command (closed-loop identification), ROS-free.

In closed loop the sensor noise reaches the coil command through the
feedback, so the command is correlated with the noise and a direct ARX (or
an IV with instruments built from the command) is biased. A known signal
``r`` added to the controller's output, *as an input disturbance* -
``u = K(x_hat) + r`` - is not correlated with the noise, and it is the
instrument of :func:`maglev_ros.sysid.iv4` (``instruments=r``). That is the
default and the only place offered here: it excites the coil inputs directly
(no reference -> position -> command path to shape) and keeps the excitation
in amperes, the unit of the command it is published beside
(``maglev/currents/excitation``). An excitation of the *reference* would be
an equally valid instrument, but it is a position (m) that the LQR turns into
a feedforward current only through the steady state, a second design choice
per sample; the input disturbance needs none.

The signals are those of :mod:`maglev_ros.excitation` (PRBS, random binary,
multisine, chirp) mapped onto the coils by a pattern (``pairs``: ``x+ = r_x``,
``x- = -r_x``, ``y+ = r_y``, ``y- = -r_y``), one period of ``length`` samples
generated once from ``seed`` (deterministic), repeated ``cycles`` times (0:
forever) from ``start`` s after the first sample. The value of a sample
depends only on its index (the samples since the first, from its stamp), so
the controller node and :class:`~maglev_ros.control.closed_loop.ClosedLoop`
add the same numbers.

The controller's own command is clipped at its ``current_limit``; the
excitation comes on top, so the total reaches ``current_limit + amplitude``
(the defaults: 1.0 + 0.1 A, the drivers' ~1.1 A). A controller that commands
zero currents (disabled, stale input, magnet lost) adds no excitation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..excitation import PATTERNS, SIGNALS, apply_pattern, excitation, pattern_signals
from ..parameters import Param, choice, integer, number
from ..topics import EXCITATION_TOPIC

__all__ = [
    'EXCITATION_PARAMETERS',
    'EXCITATION_SIGNALS',
    'CommandExcitation',
    'ExcitationSchedule',
    'LoopExcitationError',
    'excitation_from_parameters',
]

#: ``none`` (no excitation) or a signal of :mod:`maglev_ros.excitation`.
EXCITATION_SIGNALS = ('none', *SIGNALS)


class LoopExcitationError(ValueError):
    """A setting of the controller's excitation is out of range (names the value)."""


@dataclass(frozen=True)
class CommandExcitation:
    """Settings of the excitation added to the controller's command.

    The names and meanings are the excitation node's (``config/excitation_params.yaml``).

    Attributes
    ----------
    signal : str
        ``none`` (off), ``prbs``, ``random_binary``, ``multisine`` or ``chirp``.
    amplitude : float
        Peak of each signal, A (default 0.1: with the LQR's 1 A limit the
        coils stay within the drivers' ~1.1 A).
    band : tuple of float
        (low, high), fractions of the Nyquist frequency (default (0, 0.2): a
        PRBS level lasts 5 samples, its power lies below ~500 Hz at 5 kHz).
    pattern : str
        Coil pattern (:data:`maglev_ros.excitation.PATTERNS`; default
        ``pairs``: independent signals on the x and y pairs, antisymmetric).
    seed : int
        Seed of the signals.
    length : int
        Samples per period.
    cycles : int
        Periods to add (0: forever); then nothing.
    start : float
        s after the first sample at which the first period begins.
    """

    signal: str = 'none'
    amplitude: float = 0.1
    band: tuple[float, float] = (0.0, 0.2)
    pattern: str = 'pairs'
    seed: int = 0
    length: int = 25000
    cycles: int = 0
    start: float = 0.0

    def __post_init__(self) -> None:
        if self.signal not in EXCITATION_SIGNALS:
            raise LoopExcitationError(
                f'signal must be one of {", ".join(EXCITATION_SIGNALS)}, got {self.signal!r}'
            )
        if not (math.isfinite(self.amplitude) and self.amplitude >= 0):
            raise LoopExcitationError(f'amplitude must be >= 0 A, got {self.amplitude!r}')
        band = tuple(float(b) for b in self.band)
        if len(band) != 2 or not (0.0 <= band[0] < band[1] <= 1.0):
            raise LoopExcitationError(
                f'band must be (low, high) with 0 <= low < high <= 1, got {list(self.band)}'
            )
        object.__setattr__(self, 'band', band)
        if self.pattern not in PATTERNS:
            raise LoopExcitationError(
                f'pattern must be one of {", ".join(PATTERNS)}, got {self.pattern!r}'
            )
        for name, low in (('seed', 0), ('length', 1), ('cycles', 0)):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or value < low:
                raise LoopExcitationError(f'{name} must be an integer >= {low}, got {value!r}')
        if not (math.isfinite(self.start) and self.start >= 0):
            raise LoopExcitationError(f'start must be >= 0 s, got {self.start!r}')

    @property
    def enabled(self) -> bool:
        """Whether anything is added (a signal other than ``none``, amplitude > 0)."""
        return self.signal != 'none' and self.amplitude > 0

    def period(self) -> np.ndarray:
        """One period of coil currents, shape (length, 4), A (zeros when not enabled).

        Raises
        ------
        LoopExcitationError
            If the signal cannot be generated with these settings (e.g. a
            PRBS band not starting at 0).
        """
        if not self.enabled:
            return np.zeros((self.length, 4))
        try:
            signals = excitation(
                self.signal,
                self.length,
                pattern_signals(self.pattern),
                self.amplitude,
                self.band,
                self.seed,
            )
        except ValueError as err:
            raise LoopExcitationError(f'signal {self.signal}: {err}') from None
        return apply_pattern(signals, self.pattern)

    def describe(self) -> str:
        """One line for logs, e.g. ``prbs 0.1 A on pairs, band [0, 0.2], ...``."""
        if not self.enabled:
            return 'no excitation'
        return (
            f'{self.signal} {self.amplitude:g} A on {self.pattern}, band '
            f'[{self.band[0]:g}, {self.band[1]:g}], {self.length} samples x '
            f'{self.cycles or "inf"} from {self.start:g} s, seed {self.seed}'
        )


class ExcitationSchedule:
    """The excitation of each sample, by its index (samples since the first).

    Parameters
    ----------
    config : CommandExcitation
        The settings.
    sample_rate : float
        Samples per second, Hz (turns ``start`` into a sample index).

    Attributes
    ----------
    config : CommandExcitation
    start_index : int
        Index of the first excited sample.
    """

    def __init__(self, config: CommandExcitation, sample_rate: float) -> None:
        self.config = config
        self.start_index = int(round(config.start * sample_rate))
        self._period = config.period()
        self._zero = np.zeros(self._period.shape[1])
        self._end = self.start_index + config.cycles * config.length if config.cycles else math.inf

    @property
    def enabled(self) -> bool:
        """Whether anything is added."""
        return self.config.enabled

    def value(self, index: int) -> np.ndarray:
        """Currents added at sample ``index``, shape (4,), A (zeros outside the run).

        Parameters
        ----------
        index : int
            Samples since the first sample (0 for the first).
        """
        if not self.config.enabled or index < self.start_index or index >= self._end:
            return self._zero
        return self._period[(index - self.start_index) % self.config.length]

    def sequence(self, n: int) -> np.ndarray:
        """Return the currents added at samples 0 .. n-1, shape (n, 4), A.

        ``ClosedLoop.run(..., excitation=schedule.sequence(n))`` adds what the
        controller node adds.

        Parameters
        ----------
        n : int
            Number of samples.
        """
        return np.array([self.value(k) for k in range(int(n))]).reshape(int(n), -1)


_EX = CommandExcitation()
#: The excitation's settings as node parameters (``excitation_`` + each field).
EXCITATION_PARAMETERS = {
    'excitation_signal': Param(
        'none',
        f'excitation added to the command: {", ".join(EXCITATION_SIGNALS)} (published '
        f'apart on {EXCITATION_TOPIC})',
        check=choice(*EXCITATION_SIGNALS),
    ),
    'excitation_amplitude': Param(
        _EX.amplitude, 'excitation: peak of each signal, A', check=number(0)
    ),
    'excitation_band': Param(list(_EX.band), 'excitation: band (low, high), fractions of Nyquist'),
    'excitation_pattern': Param(
        _EX.pattern,
        'excitation: coil pattern (pairs: x+ = r_x, x- = -r_x, y+ = r_y, y- = -r_y)',
        check=choice(*PATTERNS),
    ),
    'excitation_seed': Param(0, 'excitation: seed of the signals', check=integer(0)),
    'excitation_length': Param(_EX.length, 'excitation: samples per period', check=integer(1)),
    'excitation_cycles': Param(0, 'excitation: periods (0: forever)', check=integer(0)),
    'excitation_start': Param(
        0.0, 'excitation: s after the first sample it starts at', check=number(0)
    ),
}


def excitation_from_parameters(values: dict) -> CommandExcitation:
    """Pop the ``excitation_*`` parameters from ``values`` into a :class:`CommandExcitation`.

    Parameters
    ----------
    values : dict
        Node parameter values; the :data:`EXCITATION_PARAMETERS` are removed.

    Raises
    ------
    LoopExcitationError
        Naming the parameter (``excitation_amplitude must ...``).
    """
    settings = {name[len('excitation_') :]: values.pop(name) for name in EXCITATION_PARAMETERS}
    try:
        return CommandExcitation(**settings)
    except LoopExcitationError as err:
        raise LoopExcitationError(f'excitation_{err}') from err
