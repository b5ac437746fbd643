"""An observer of the lab session that identifies an ARX model online, ROS-free.

The recursive ARX core the identifier node runs
(:class:`~maglev_ros.sysid.online.OnlineArx`) on the recorded samples, with
the pairing of the bag converter: each sample's outputs (field components of
its reading) with the inputs in force at it, either the command that drives
the coils from it (held until the next: :class:`~maglev_ros.loop.WindowSample`)
or the currents the plant reports for it (a board's applied PWM). Inputs are
linear combinations of the coils (the antisymmetric pairs ``0.5 (c+ - c-)``).
Samples are buffered and added a batch at a time (``update_many``, one
compiled call: bit for bit the same as one by one).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..sysid.online import OnlineArx, load_kernels
from .session import WindowSample

__all__ = ['PAIR_INPUTS', 'OnlineEstimate', 'OnlineIdentifier']

#: The antisymmetric pair inputs u_x = 0.5 (x+ - x-), u_y = 0.5 (y+ - y-) of the 4 coils.
PAIR_INPUTS = np.array([[0.5, -0.5, 0.0, 0.0], [0.0, 0.0, 0.5, -0.5]])


@dataclass(frozen=True)
class OnlineEstimate:
    """The online identifier's final state.

    Attributes
    ----------
    model : PolyModel
        Its ARX estimate (all rows), raw (not detrended) signals.
    samples : int
        Samples it was given.
    covariance_trace : float
        Trace of its covariance.
    fit : ndarray, shape (ny,)
        One-step prediction fit over its window, %.
    forgetting : float
        Its forgetting factor.
    """

    model: object
    samples: int
    covariance_trace: float
    fit: np.ndarray
    forgetting: float


class OnlineIdentifier:
    """Recursive ARX of field components against coil inputs, fed with recorded samples.

    Parameters
    ----------
    outputs : sequence of int
        Columns of the reading taken as outputs (``3 k + axis``: sensor k's x, y, z).
    inputs : ndarray, shape (nu, n_s)
        Input ``i`` is ``inputs[i] @ coils`` (default :data:`PAIR_INPUTS`).
    source : {'command', 'currents'}
        The coils' values: the command in force, or the plant's currents.
    na : int or array_like (ny, ny)
    nb, nk : int or array_like (ny, nu)
        ARX orders and delays, samples.
    forgetting : float
        Forgetting factor in (0, 1].
    initial_covariance : float
        ``P0 = p0 I`` (fields in T: large).
    batch : int
        Samples added at once.
    names : (sequence of str, sequence of str)
        The model's output and input names.
    """

    def __init__(
        self,
        outputs: Sequence[int] = (0, 1),
        inputs: np.ndarray = PAIR_INPUTS,
        source: str = 'command',
        na=((7, 0), (0, 6)),
        nb=((9, 0), (0, 6)),
        nk=1,
        forgetting: float = 1.0,
        initial_covariance: float = 1e10,
        batch: int = 500,
        names: tuple[Sequence[str], Sequence[str]] = (('Bx_0', 'By_0'), ('u_x', 'u_y')),
    ) -> None:
        if source not in ('command', 'currents'):
            raise ValueError(f"source must be 'command' or 'currents', got {source!r}")
        self.outputs = np.asarray(outputs, dtype=np.intp)
        self.inputs = np.asarray(inputs, dtype=float)
        self.source = source
        self.batch = int(batch)
        self.names = names
        self.arx = OnlineArx(
            na,
            nb,
            nk,
            ny=len(self.outputs),
            nu=self.inputs.shape[0],
            forgetting=forgetting,
            initial_covariance=initial_covariance,
        )
        # the compiled update loads now (0.3-1.5 s holding the GIL), not in a real-time run
        load_kernels()
        self._held = np.zeros(self.inputs.shape[1])
        self._y: list[np.ndarray] = []
        self._u: list[np.ndarray] = []

    def __call__(self, item: WindowSample) -> None:
        """Take one recorded sample (added with the next batch)."""
        s = item.sample
        if self.source == 'currents':
            coils = s.currents
        else:
            if item.command is not None:
                self._held = item.command
            coils = self._held
        self._y.append(s.reading[self.outputs])
        self._u.append(self.inputs @ coils)
        if len(self._y) >= self.batch:
            self.flush()

    def flush(self) -> None:
        """Add the samples taken so far."""
        if self._y:
            y, u = np.array(self._y), np.array(self._u)
            self._y, self._u = [], []
            self.arx.update_many(y, u)

    @property
    def samples(self) -> int:
        """Samples added (after :meth:`flush`)."""
        return int(self.arx.samples)

    def estimate(self, Ts: float) -> OnlineEstimate | None:
        """Add what is pending and return the estimate (None: no sample).

        Parameters
        ----------
        Ts : float
            The model's sample time, s.
        """
        self.flush()
        if not self.arx.samples:
            return None
        st = self.arx.status()
        return OnlineEstimate(
            self.arx.model(Ts, *self.names),
            int(self.arx.samples),
            float(st.covariance_trace),
            np.asarray(st.fit),
            self.arx.forgetting,
        )

    def close(self) -> None:
        """Add what is pending."""
        self.flush()
