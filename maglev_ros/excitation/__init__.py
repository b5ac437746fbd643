"""Identification inputs (ROS-free): PRBS, random binary, multisine, chirp, coil patterns.

Bands are fractions of the Nyquist frequency, ``(low, high)`` in [0, 1], as in
MATLAB's ``idinput``. Patterns map the generated signals onto the four
solenoids (order x+, x-, y+, y-), e.g. the antisymmetric pairs the board
uses: +u on x+ and -u on x-.
"""

from .patterns import PATTERNS, apply_pattern, pattern_matrix, pattern_signals
from .sequence import CommandSequence
from .signals import SIGNALS, chirp, excitation, multisine, prbs, random_binary

__all__ = [
    'CommandSequence',
    'PATTERNS',
    'SIGNALS',
    'apply_pattern',
    'chirp',
    'excitation',
    'multisine',
    'pattern_matrix',
    'pattern_signals',
    'prbs',
    'random_binary',
]
