"""OnlineArx cost per sample: the compiled update against the per-sample numpy code, same run.

Configuration (the identifier node's, 5 kHz)::

    OnlineArx([[7, 0], [0, 6]], [[9, 0], [0, 6]], [[1, 1], [1, 1]], 2, 2,
              initial_covariance=1e10)

Three ways to feed the same ``--samples`` random samples (white Gaussian
``y``, ``u``), each from a fresh estimator:

* baseline: :class:`BaselineArx` below, a faithful copy of the per-sample
  numpy ``OnlineArx.update`` that preceded the compiled kernel (no window);
* ``OnlineArx.update``: one compiled call per sample;
* ``OnlineArx.update_many``: bursts of ``--burst`` samples (default 5), one
  compiled call per burst.

All three must give the same parameters, covariance and prediction errors bit
for bit (checked).  Cost: the best of ``--repeat`` runs of CPU time
(``time.thread_time``) per sample, single-threaded BLAS; the numba cache is
warmed first.

Usage::

    python benchmarks/online_arx.py
    python benchmarks/online_arx.py --samples 50000 --burst 10
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402

import numpy as np  # noqa: E402

from maglev_ros.sysid.online import OnlineArx  # noqa: E402
from maglev_ros.sysid.orders import make_orders  # noqa: E402
from maglev_ros.sysid.rls import rls_step  # noqa: E402

NA, NB, NK = [[7, 0], [0, 6]], [[9, 0], [0, 6]], [[1, 1], [1, 1]]
NY, NU, P0 = 2, 2, 1e10


class BaselineArx:
    """The per-sample numpy ``OnlineArx.update`` (before the compiled kernel), no window.

    Parameters
    ----------
    na, nb, nk : object
        Orders as :class:`OnlineArx`.
    ny, nu : int
        Numbers of outputs and inputs.
    forgetting : float
        Forgetting factor in (0, 1].
    initial_covariance : float
        ``p0`` of ``P0 = p0 I``.
    fit_window : int
        Samples of the prediction-fit window.
    wait_for_history : bool
        Update a row only once its regressor is complete.
    """

    def __init__(
        self,
        na: object,
        nb: object,
        nk: object = 1,
        ny: int = 1,
        nu: int = 1,
        forgetting: float = 1.0,
        initial_covariance: float = 1e4,
        fit_window: int = 1000,
        wait_for_history: bool = True,
    ) -> None:
        self.orders = make_orders(ny, nu, na=na, nb=nb, nk=nk)
        self.forgetting = float(forgetting)
        self.initial_covariance = float(initial_covariance)
        self.fit_window = int(fit_window)
        self.wait_for_history = bool(wait_for_history)
        o = self.orders
        self._ylags = max(1, int(o.na.max(initial=0)))
        self._ulags = max(1, int((o.nk + o.nb).max(initial=1)))
        self._index = []
        for i in range(o.ny):
            idx = []
            for j in range(o.ny):
                idx += [j * self._ylags + lag - 1 for lag in range(1, o.na[i, j] + 1)]
            base = o.ny * self._ylags
            for j in range(o.nu):
                k = int(o.nk[i, j])
                idx += [base + j * self._ulags + lag for lag in range(k, k + o.nb[i, j])]
            self._index.append(np.array(idx, dtype=np.intp))
        self._starts = [o.row_start(i) for i in range(o.ny)]
        self._sizes = o.row_sizes()
        self._yh = np.zeros((o.ny, self._ylags))
        self._uh = np.zeros((o.nu, self._ulags))
        self._theta = [np.zeros(s) for s in self._sizes]
        self._P = [self.initial_covariance * np.eye(s) for s in self._sizes]
        self.samples = 0
        self._updates = np.zeros(o.ny, dtype=np.int64)
        self._last_error = np.full(o.ny, np.nan)
        self._fit_y = np.full((self.fit_window, o.ny), np.nan)
        self._fit_e = np.full((self.fit_window, o.ny), np.nan)

    @property
    def theta(self) -> np.ndarray:
        """Current parameters, shape (n_params,)."""
        return np.concatenate(self._theta)

    def update(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Add ``y(t)`` (ny,), ``u(t)`` (nu,); return the prediction error (ny,)."""
        o = self.orders
        y = np.atleast_1d(np.asarray(y, dtype=float))
        u = np.atleast_1d(np.asarray(u, dtype=float))
        if y.shape != (o.ny,) or u.shape != (o.nu,):
            raise ValueError(
                f'update needs y of shape ({o.ny},) and u of shape ({o.nu},), '
                f'got {y.shape} and {u.shape}'
            )
        if not (np.all(np.isfinite(y)) and np.all(np.isfinite(u))):
            raise ValueError(f'samples must be finite, got y={y.tolist()} u={u.tolist()}')
        self._uh[:, 1:] = self._uh[:, :-1]
        self._uh[:, 0] = u
        flat = np.concatenate([-self._yh.ravel(), self._uh.ravel()])
        errors = np.full(o.ny, np.nan)
        for i in range(o.ny):
            if self.wait_for_history and self.samples < self._starts[i]:
                continue
            phi = flat[self._index[i]]
            errors[i] = rls_step(self._P[i], self._theta[i], phi, float(y[i]), self.forgetting)
            self._updates[i] += 1
        self._yh[:, 1:] = self._yh[:, :-1]
        self._yh[:, 0] = y
        slot = self.samples % self.fit_window
        self._fit_y[slot] = y
        self._fit_e[slot] = errors
        self._last_error = errors
        self.samples += 1
        return errors


def per_sample(
    run: Callable[[], tuple[object, np.ndarray]], n: int, repeat: int
) -> tuple[float, object, np.ndarray]:
    """Best CPU time per sample of ``run`` over ``repeat`` runs, us; its last estimator and errors.

    Parameters
    ----------
    run : callable
        Feeds ``n`` samples to a fresh estimator; returns it and the errors (n, ny).
    n : int
        Samples per run.
    repeat : int
        Runs.
    """
    best = np.inf
    for _ in range(repeat):
        start = time.thread_time()
        estimator, errors = run()
        best = min(best, time.thread_time() - start)
    return best / n * 1e6, estimator, errors


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=20_000, help='samples per run')
    parser.add_argument('--burst', type=int, default=5, help='samples per update_many call')
    parser.add_argument('--repeat', type=int, default=5, help='runs (best is kept)')
    parser.add_argument('--seed', type=int, default=0)
    args = parser.parse_args(argv)
    n, burst = args.samples, args.burst
    rng = np.random.default_rng(args.seed)
    Y, U = rng.standard_normal((n, NY)), rng.standard_normal((n, NU))
    rows = [(Y[t], U[t]) for t in range(n)]  # the node hands update one (ny,), (nu,) pair

    def baseline() -> tuple[object, np.ndarray]:
        arx = BaselineArx(NA, NB, NK, NY, NU, initial_covariance=P0)
        return arx, [arx.update(y, u) for y, u in rows]

    def update() -> tuple[object, np.ndarray]:
        arx = OnlineArx(NA, NB, NK, NY, NU, initial_covariance=P0)
        return arx, [arx.update(y, u) for y, u in rows]

    def update_many() -> tuple[object, np.ndarray]:
        arx = OnlineArx(NA, NB, NK, NY, NU, initial_covariance=P0)
        starts = range(0, n, burst)
        return arx, [arx.update_many(Y[t : t + burst], U[t : t + burst]) for t in starts]

    warm = OnlineArx(NA, NB, NK, NY, NU, initial_covariance=P0)  # compile / load the cache
    warm.update(Y[0], U[0])
    warm.update_many(Y[:burst], U[:burst])

    t_base, base, e_base = per_sample(baseline, n, args.repeat)
    t_one, one, e_one = per_sample(update, n, args.repeat)
    t_many, many, e_many = per_sample(update_many, n, args.repeat)
    e_base = np.array(e_base)
    for arx, errors in ((one, np.array(e_one)), (many, np.vstack(e_many))):
        np.testing.assert_array_equal(errors, e_base)
        np.testing.assert_array_equal(arx.theta, base.theta)
        for P, P_base in zip(arx._P, base._P, strict=True):
            np.testing.assert_array_equal(P, P_base)

    print(f'OnlineArx na={NA} nb={NB} nk={NK}, p0={P0:g}: {n} samples, best of {args.repeat}')
    print(f'{"method":<28}{"us/sample":>10}{"speed-up":>10}')
    print(f'{"baseline (numpy update)":<28}{t_base:>10.2f}{1.0:>10.1f}')
    print(f'{"update":<28}{t_one:>10.2f}{t_base / t_one:>10.1f}')
    print(f'{f"update_many (n={burst})":<28}{t_many:>10.2f}{t_base / t_many:>10.1f}')
    print('theta, P and errors identical bit for bit: yes')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
