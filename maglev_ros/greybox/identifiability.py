"""Which free parameters a data set identifies: sensitivity, rank and correlation.

The analysis works on the Jacobian of the weighted residuals with respect to
the scaled parameters (a unit step is a parameter's ``scale``):

* a column that is (numerically) zero: the parameter has **no effect** on
  these data (the levitating magnet's mass on static data);
* columns that are linearly dependent (rank deficiency, found by QR with
  column pivoting on unit-norm columns): only a **combination** of those
  parameters is identified; the pivoting keeps the best-determined ones and
  holds the others at their nominal value.

Both are reported, never dropped silently. After the fit, strongly correlated
estimates (|r| > 0.95) are listed as well.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.linalg import qr

from .parameters import ParameterSpec

__all__ = ['Unidentified', 'Identifiability', 'analyse', 'correlated_pairs']

#: A column below this fraction of the largest column norm has no effect.
NO_EFFECT = 1e-9
#: Pivoted-QR diagonal (unit-norm columns) below which a column is dependent.
DEPENDENT = 1e-7


@dataclass(frozen=True)
class Unidentified:
    """A free parameter the data do not identify.

    Attributes
    ----------
    name : str
        The parameter.
    reason : {'no effect', 'combination'}
        Zero sensitivity, or only a combination with ``partners`` is identified.
    partners : tuple of str
        The parameters it is confounded with (for ``combination``).
    """

    name: str
    reason: str
    partners: tuple[str, ...] = ()

    def line(self) -> str:
        """One sentence for people."""
        if self.reason == 'no effect':
            return (
                f'{self.name}: not identifiable, these data do not depend on it; held at nominal'
            )
        return (
            f'{self.name}: not identifiable, only its combination with '
            f'{", ".join(self.partners)} is; held at nominal'
        )


@dataclass(frozen=True)
class Identifiability:
    """Result of :func:`analyse`.

    Attributes
    ----------
    names : tuple of str
        The free parameters analysed.
    rank : int
        Numerical rank of the scaled Jacobian.
    unidentified : tuple of Unidentified
        Free parameters the data do not identify.
    singular_values : ndarray
        Singular values of the unit-column Jacobian of the sensitive parameters.
    """

    names: tuple[str, ...]
    rank: int
    unidentified: tuple[Unidentified, ...]
    singular_values: np.ndarray

    @property
    def unidentified_names(self) -> tuple[str, ...]:
        """Names of the unidentified parameters."""
        return tuple(u.name for u in self.unidentified)

    def lines(self) -> list[str]:
        """Return the report, one line per unidentified parameter (plus the rank)."""
        head = f'identifiability: rank {self.rank} of {len(self.names)} free parameters'
        return [head, *(u.line() for u in self.unidentified)]


def analyse(jacobian: np.ndarray, specs: Sequence[ParameterSpec]) -> Identifiability:
    """Find the free parameters that a residual Jacobian does not identify.

    Parameters
    ----------
    jacobian : ndarray, shape (m, p)
        d residual / d scaled parameter.
    specs : sequence of ParameterSpec
        The ``p`` free parameters, in column order.

    Returns
    -------
    Identifiability
    """
    names = tuple(s.name for s in specs)
    jac = np.asarray(jacobian, dtype=float)
    norms = np.linalg.norm(jac, axis=0)
    top = norms.max() if norms.size else 0.0
    out: list[Unidentified] = []
    sensitive = [i for i in range(len(names)) if top > 0 and norms[i] > NO_EFFECT * top]
    out += [Unidentified(names[i], 'no effect') for i in range(len(names)) if i not in sensitive]
    if not sensitive:
        return Identifiability(names, 0, tuple(out), np.zeros(0))
    unit = jac[:, sensitive] / norms[sensitive]
    _, r, piv = qr(unit, mode='economic', pivoting=True)
    diag = np.abs(np.diag(r))
    rank = int(np.sum(diag > DEPENDENT))
    kept = [sensitive[i] for i in piv[:rank]]
    for col in piv[rank:]:
        i = sensitive[col]
        coef, *_ = np.linalg.lstsq(unit[:, [sensitive.index(k) for k in kept]], unit[:, col])
        big = np.abs(coef) > 0.05 * np.abs(coef).max()
        partners = tuple(names[k] for k, b in zip(kept, big, strict=True) if b)
        out.append(Unidentified(names[i], 'combination', partners))
    singular = np.linalg.svd(unit, compute_uv=False)
    order = {n: k for k, n in enumerate(names)}
    out.sort(key=lambda u: order[u.name])
    return Identifiability(names, rank, tuple(out), singular)


def correlated_pairs(
    names: Sequence[str], correlation: np.ndarray, threshold: float = 0.95
) -> tuple[tuple[str, str, float], ...]:
    """Pairs of estimates whose correlation exceeds ``threshold`` in magnitude.

    Parameters
    ----------
    names : sequence of str
        Parameter names, in the matrix order.
    correlation : ndarray, shape (n, n)
        Correlation matrix of the estimates.
    threshold : float
        Pairs with |r| above this are returned.
    """
    pairs = []
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            r = float(correlation[i, j])
            if abs(r) > threshold:
                pairs.append((names[i], names[j], r))
    return tuple(sorted(pairs, key=lambda p: -abs(p[2])))
