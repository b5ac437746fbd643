"""Pole-zero pairs that nearly cancel: the mark of orders above the data's.

A model of higher order than the system that produced the data spends its
extra poles and zeros on nothing: they come out in pairs that (nearly) cancel,
and nothing in the data holds them inside the unit circle. Instrumental-variable
estimates (``iv4``) are the usual victims: their extra poles wander freely,
often outside the unit circle, and the simulated output diverges although the
model's input-output behaviour is fine. MATLAB's toolbox leaves this to the
user (``pzmap`` with confidence regions, ``minreal``, ``balred``); here the
pairs are found and removed, which gives the model of the order the data
support.

Two roots ``p`` (pole) and ``z`` (zero) cancel when
``|p - z| <= tol * max(1, |p|)``; each pole is matched to its nearest zero,
largest poles first, and only conjugate-closed sets are removed, so the reduced
polynomials stay real. Single-input single-output ARX, IV and ARMAX models only
(the pairs of ``A`` and ``B``; ``C`` is kept).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .model import PolyModel
from .orders import make_orders

__all__ = ['CANCEL_TOL', 'cancelling_pairs', 'root_text', 'without_cancelling_pairs']

CANCEL_TOL = 0.02  # relative distance |p - z| / max(1, |p|) of a cancelling pair
_REDUCIBLE = ('arx', 'iv4', 'armax')


def _reducible(model: PolyModel) -> bool:
    o = model.orders
    return model.ny == 1 and model.nu == 1 and model.structure in _REDUCIBLE and not o.nf.any()


def cancelling_pairs(model: PolyModel, tol: float = CANCEL_TOL) -> list[tuple[complex, complex]]:
    """Pole-zero pairs of a SISO ARX/IV/ARMAX model that nearly cancel.

    Parameters
    ----------
    model : PolyModel
        The model (other structures and MIMO models have no pairs here).
    tol : float
        Relative distance ``|p - z| / max(1, |p|)`` below which a pair cancels.

    Returns
    -------
    list of (complex, complex)
        ``(pole, zero)`` pairs, largest poles first; empty if none.
    """
    if not _reducible(model):
        return []
    poles = sorted(np.roots(model.polynomial('A')), key=lambda p: -abs(p))
    zeros = list(model.zeros())
    pairs = []
    for p in poles:
        if not zeros:
            break
        k = int(np.argmin([abs(p - z) for z in zeros]))
        if abs(p - zeros[k]) <= tol * max(1.0, abs(p)):
            pairs.append((complex(p), complex(zeros.pop(k))))
    return pairs


def _remove(roots: np.ndarray, removed: list[complex]) -> np.ndarray:
    left = list(roots)
    for r in removed:
        left.pop(int(np.argmin([abs(r - x) for x in left])))
    return np.asarray(left, dtype=complex)


def without_cancelling_pairs(model: PolyModel, tol: float = CANCEL_TOL) -> PolyModel | None:
    """Return the model with its cancelling pole-zero pairs removed.

    Parameters
    ----------
    model : PolyModel
        A SISO ARX, IV or ARMAX model.
    tol : float
        See :func:`cancelling_pairs`.

    Returns
    -------
    PolyModel or None
        Same structure, ``na`` and ``nb`` lowered by the number of pairs, the
        leading ``B`` coefficient kept, no covariance (the reduction is not an
        estimate); None if no pair cancels or the pairs are not conjugate-closed.
    """
    pairs = cancelling_pairs(model, tol)
    if not pairs:
        return None
    poles = _remove(np.roots(model.polynomial('A')), [p for p, _ in pairs])
    zeros = _remove(model.zeros(), [z for _, z in pairs])
    a, b_monic = np.atleast_1d(np.poly(poles)), np.atleast_1d(np.poly(zeros))
    if (
        np.max(np.abs(np.imag(a)), initial=0) > 1e-9
        or np.max(np.abs(np.imag(b_monic)), initial=0) > 1e-9
    ):
        return None  # an unpaired conjugate: the reduced polynomials would be complex
    o = model.orders
    b_full = np.trim_zeros(model.polynomial('B'), 'f')
    b = b_full[0] * np.real(b_monic)
    na, nb = int(o.na[0, 0]) - len(pairs), int(o.nb[0, 0]) - len(pairs)
    orders = make_orders(1, 1, na=na, nb=nb, nk=int(o.nk[0, 0]), nc=int(o.nc[0]))
    c = model.polynomial('C')[1:] if o.nc[0] else np.zeros(0)
    theta = np.concatenate([np.real(a)[1:], b, c])
    return dataclasses.replace(model, orders=orders, theta=theta, covariance=None, report=None)


def root_text(root: complex) -> str:
    """Short text of a pole or zero: ``0.95``, ``0.43+0.92j``.

    Parameters
    ----------
    root : complex
        The pole or zero.

    Returns
    -------
    str
    """
    root = complex(root)
    if abs(root.imag) <= 1e-9 * max(1.0, abs(root)):
        return f'{root.real:.3g}'
    return f'{root.real:.3g}{root.imag:+.3g}j'
