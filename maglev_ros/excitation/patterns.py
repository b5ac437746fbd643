"""Map excitation signals onto the four solenoids (order x+, x-, y+, y-).

A pattern is a 4 x m matrix M: commands = signals @ M.T for m signals.
"""

from __future__ import annotations

import numpy as np

__all__ = ['PATTERNS', 'apply_pattern', 'pattern_matrix', 'pattern_signals']

_MATRICES = {
    # +u_x on x+, -u_x on x-, +u_y on y+, -u_y on y-: the board's antisymmetric pairs
    'pairs': [[1, 0], [-1, 0], [0, 1], [0, -1]],
    'x_pair': [[1], [-1], [0], [0]],
    'y_pair': [[0], [0], [1], [-1]],
    'independent': np.eye(4).tolist(),
    'common': [[1], [1], [1], [1]],  # same current in every coil (vertical force)
}
PATTERNS = tuple(_MATRICES)


def pattern_matrix(pattern: str) -> np.ndarray:
    """Return the 4 x m mixing matrix of a pattern.

    Parameters
    ----------
    pattern : str
        One of :data:`PATTERNS`.

    Returns
    -------
    ndarray, shape (4, m)
    """
    if pattern not in _MATRICES:
        raise ValueError(f'pattern must be one of {", ".join(PATTERNS)}, got {pattern!r}')
    return np.array(_MATRICES[pattern], dtype=float)


def pattern_signals(pattern: str) -> int:
    """Return the number of independent signals a pattern takes.

    Parameters
    ----------
    pattern : str
        A coil pattern (:data:`PATTERNS`).
    """
    return pattern_matrix(pattern).shape[1]


def apply_pattern(signals: np.ndarray, pattern: str, offset=0.0) -> np.ndarray:
    """Coil commands from signals.

    Parameters
    ----------
    signals : array_like, shape (N, m)
        One column per signal (m = :func:`pattern_signals`).
    pattern : str
        One of :data:`PATTERNS`.
    offset : float or array_like, shape (4,)
        Added to every command, A.

    Returns
    -------
    ndarray, shape (N, 4)
        Currents x+, x-, y+, y-.
    """
    matrix = pattern_matrix(pattern)
    values = np.asarray(signals, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    if values.ndim != 2 or values.shape[1] != matrix.shape[1]:
        raise ValueError(
            f'pattern {pattern!r} takes {matrix.shape[1]} signal column(s), '
            f'got shape {values.shape}'
        )
    return values @ matrix.T + np.broadcast_to(np.asarray(offset, dtype=float), (4,))
