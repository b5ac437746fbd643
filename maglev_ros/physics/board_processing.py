"""What a V4x PC-control firmware does to the field before a host sees it.

The board (``shared/docs/teensy-protocol.md``, "V4x PC-control firmware")
averages its sensor at power-up as a *baseline*, measures each coil's direct
*feedthrough* into the sensor's x and y axes, and then reports every sample as::

    b = raw - baseline + feedthrough compensation      (x, y: coil field removed)
    f_x = 0.2 b_x + 0.8 f_x(prev),  f_y likewise        (per board sample, 5 kHz)
    f_z = b_z                                           (z is not filtered)

So the host receives the field of whatever changed since power-up (the
levitating magnet, if it was absent then), without the coils' own field on x
and y, low-pass filtered on x and y: not the raw field the physics model
predicts.  :class:`BoardProcessing` is that map for the model: the baseline
and feedthrough are the model's own (magnet absent, zero currents; field per
ampere of each coil), which is what the firmware measures on a board the model
describes.  It is used explicitly (``maglev-calibrate --measurement board``),
never inferred from the data.

Between two host samples the board runs ``M = Ts / board_period`` filter
steps; for a signal held over the host period the filter is, at the host rate,
``f_k = a f_(k-1) + (1 - a) b_k`` with ``a = 0.8^M``.  :func:`augment` adds
these filter states to a discrete linear model (the grey-box's).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ['BOARD_PERIOD', 'FILTER_WEIGHT', 'PAIRS', 'BoardProcessing', 'augment', 'augment_exact']

#: The firmware's loop period, s (5 kHz).
BOARD_PERIOD = 2e-4
#: The coil pairs (x+, x-) and (y+, y-): the board drives each antisymmetrically.
PAIRS = ((0, 1), (2, 3))
#: Weight of the new sample in the firmware's x/y low-pass (``f = 0.2 raw + 0.8 f``).
FILTER_WEIGHT = 0.2


@dataclass(frozen=True)
class BoardProcessing:
    """The firmware's field processing for the channels ``[Bx_0, By_0, Bz_0, Bx_1, ...]``.

    Attributes
    ----------
    baseline : ndarray, shape (p,)
        Field at power-up (magnet absent, coils off), T.
    feedthrough : ndarray, shape (p, n_coils)
        Coil field removed per ampere, T/A (zero on z channels: the firmware
        compensates x and y only).
    filtered : ndarray of bool, shape (p,)
        Channels the firmware low-pass filters (x and y).
    weight : float
        New-sample weight of the low-pass per board step.
    board_period : float
        Board loop period, s.
    """

    baseline: np.ndarray
    feedthrough: np.ndarray
    filtered: np.ndarray
    weight: float = FILTER_WEIGHT
    board_period: float = BOARD_PERIOD

    @classmethod
    def from_model(cls, model, sensors=None, pairs=None) -> BoardProcessing:
        """Return the processing a board that the physics model describes would apply.

        Parameters
        ----------
        model : MaggyModel
            The physics model (its parameter set).
        sensors : sequence of int, optional
            Sensors whose channels are kept (default all).
        pairs : array_like, shape (p, 2), optional
            The board's processed field per ampere of each coil pair, T/A, as
            measured with the magnet absent
            (:func:`maglev_ros.hardware.v4x_pc_feedthrough.measure_feedthrough`;
            columns: the x pair, the y pair; rows: the kept channels). The
            firmware measures its own compensation with a few percent of error;
            given this, the feedthrough is corrected so that the processed field
            of each pair is the measured one (only the pairs' differences reach
            the coils: the correction is split evenly, antisymmetric, between a
            pair's two coils). Default: the model's own compensation, exact.

        Returns
        -------
        BoardProcessing
            Baseline and feedthrough of the model's own field.
        """
        base, raw = _coil_field(model, sensors)
        board = cls._compensating(base, raw)
        return board if pairs is None else board.with_pairs(raw, pairs)

    @classmethod
    def _compensating(cls, base: np.ndarray, raw: np.ndarray) -> BoardProcessing:
        """Return the board compensating x and y by the coils' own field ``raw`` (p, 4), T/A."""
        axes = np.arange(base.size) % 3
        feed = raw.copy()
        feed[axes == 2] = 0.0  # z is not compensated
        return cls(base, feed, axes < 2)

    @classmethod
    def model_pairs(cls, model, sensors=None) -> np.ndarray:
        """Return the processed field per ampere of each coil pair of the model's board, T/A.

        Zero on x and y (the model's compensation is exact); the coils' own
        field on z.

        Parameters
        ----------
        model : MaggyModel
            The physics model.
        sensors : sequence of int, optional
            Sensors whose channels are kept (default all).

        Returns
        -------
        ndarray, shape (p, 2)
        """
        base, raw = _coil_field(model, sensors)
        return cls._compensating(base, raw).pair_response(raw)

    def pair_response(self, raw: np.ndarray) -> np.ndarray:
        """Return the processed field per ampere of each coil pair, T/A, shape (p, 2).

        Parameters
        ----------
        raw : ndarray, shape (p, 4)
            The coils' raw field per ampere (order x+, x-, y+, y-), T/A.
        """
        processed = np.asarray(raw, dtype=float) - self.feedthrough
        return np.column_stack([processed[:, a] - processed[:, b] for a, b in PAIRS])

    def with_pairs(self, raw: np.ndarray, pairs) -> BoardProcessing:
        """Return this processing with its feedthrough corrected to a measured pair response.

        Parameters
        ----------
        raw : ndarray, shape (p, 4)
            The coils' raw field per ampere, T/A (the model's).
        pairs : array_like, shape (p, 2)
            Measured processed field per ampere of the x and the y pair, T/A.

        Raises
        ------
        ValueError
            If ``pairs`` is not finite or has the wrong shape.
        """
        pairs = np.asarray(pairs, dtype=float)
        if pairs.shape != (self.baseline.size, 2) or not np.all(np.isfinite(pairs)):
            raise ValueError(
                f'pairs must be finite, shape ({self.baseline.size}, 2), got {pairs.shape}'
            )
        excess = self.pair_response(raw) - pairs  # what the board removes beyond the model
        feed = self.feedthrough.copy()
        for (a, b), col in zip(PAIRS, excess.T, strict=True):
            feed[:, a] += col / 2
            feed[:, b] -= col / 2
        return BoardProcessing(self.baseline, feed, self.filtered, self.weight, self.board_period)

    def host_pole(self, Ts: float) -> float:
        """Return the pole ``a`` of the x/y low-pass at the host's sample time.

        Parameters
        ----------
        Ts : float
            Host sample time, s.
        """
        steps = max(Ts / self.board_period, 1.0)
        return float((1.0 - self.weight) ** steps)

    def board_steps(self, Ts: float) -> int:
        """Return the board's filter steps per host sample, ``round(Ts / board_period)`` (>= 1).

        Parameters
        ----------
        Ts : float
            Host sample time, s.
        """
        return max(1, int(round(Ts / self.board_period)))

    def noise_injection(self, Ts: float) -> float:
        """Return the noise variance a filter state takes in over one host sample, per unit.

        The board filters a fresh sensor reading at each of its ``M`` steps, so
        white sensor noise of variance ``s^2`` per board step enters the filter
        state once per host sample with variance ``s^2 w^2 sum_j (1 - w)^(2 j)``
        (``j < M``, ``w``: :attr:`weight`): the readings of a filtered channel
        carry coloured noise (a first-order lag of white noise at the host
        rate), not white noise.

        Parameters
        ----------
        Ts : float
            Host sample time, s.

        Returns
        -------
        float
            That variance per unit sensor variance (dimensionless).
        """
        keep = (1.0 - self.weight) ** 2
        return float(self.weight**2 * sum(keep**j for j in range(self.board_steps(Ts))))

    def sensor_noise(self, level: np.ndarray, Ts: float) -> np.ndarray:
        """Return the sensor noise behind a filtered channel's readings, T rms per board step.

        ``level`` is what :func:`maglev_ros.greybox.noise_level` measures on
        the readings the host receives (second differences, taken as white).
        For the filtered noise ``f_k = a f_(k-1) + n_k`` (``a``:
        :meth:`host_pole`, ``var n = s^2`` :meth:`noise_injection`) the second
        difference has the variance ``var n * sum_i h_i^2`` (``h``: the impulse
        response of ``(1 - z^-1)^2 / (1 - a z^-1)``), which gives ``s``.

        Parameters
        ----------
        level : array_like
            Noise level of the received readings, T rms (white-noise reading).
        Ts : float
            Host sample time, s.

        Returns
        -------
        ndarray
            Sensor noise, T rms, same shape as ``level``.
        """
        a = self.host_pole(Ts)
        h2 = 1.0 + (a - 2.0) ** 2 + (1.0 - a) ** 4 / (1.0 - a * a)
        return np.asarray(level, dtype=float) * np.sqrt(6.0 / (h2 * self.noise_injection(Ts)))

    def host_filter(
        self, A: np.ndarray, G: np.ndarray, C: np.ndarray, D: np.ndarray, Ts: float
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """Return the filtered channels' update over one host sample, exact at the board steps.

        With the inputs ``w`` held over the host sample (from its start) and
        the continuous model ``dx/dt = A x + G w``, the board takes ``M =
        Ts / board_period`` samples ``b_j = C x(j dt_b) + D w`` in the host
        sample and filters each: the filter output at the next host sample is
        ``f+ = a f + Fx x + Fw w`` with ``a = 0.8^M``. (The host-rate
        approximation of :meth:`host_pole` takes ``b`` at the sample's end
        for all ``M`` steps: a phase lead of about 1.5 board steps.)

        Parameters
        ----------
        A : ndarray, shape (n, n)
            Continuous dynamics, 1/s.
        G : ndarray, shape (n, r)
            Continuous input matrix of the held inputs (currents first).
        C : ndarray, shape (q, n)
            The filtered channels' output matrix (processed: raw C).
        D : ndarray, shape (q, r)
            Their direct term (processed: feedthrough removed; zero for
            inputs that are not currents).
        Ts : float
            Host sample time, s (a multiple of the board period; otherwise
            rounded to whole board steps).

        Returns
        -------
        Fx : ndarray, shape (q, n)
        Fw : ndarray, shape (q, r)
        a : float
            ``(1 - weight)^M``.
        """
        from scipy.linalg import expm

        n, r = G.shape
        steps = self.board_steps(Ts)
        big = np.zeros((n + r, n + r))
        big[:n, :n], big[:n, n:] = A, G
        e = expm(big * self.board_period)
        phi, gam = e[:n, :n], e[:n, n:]
        keep = 1.0 - self.weight
        power, held = np.eye(n), np.zeros((n, r))
        fx, fw = np.zeros((C.shape[0], n)), np.zeros((C.shape[0], r))
        for j in range(1, steps + 1):
            power, held = phi @ power, phi @ held + gam  # x(j dt_b) = power x + held w
            w = self.weight * keep ** (steps - j)
            fx += w * (C @ power)
            fw += w * (C @ held + D)
        return fx, fw, float(keep**steps)

    def apply(self, raw: np.ndarray, currents: np.ndarray, Ts: float) -> np.ndarray:
        """Process a raw field record as the firmware would (host-rate filter).

        Parameters
        ----------
        raw : ndarray, shape (N, p)
            Raw field, T (what the physics model predicts).
        currents : ndarray, shape (N, n_coils)
            Coil currents, A.
        Ts : float
            Host sample time, s.

        Returns
        -------
        ndarray, shape (N, p)
            What the host receives, T; the filter starts settled on the first sample.
        """
        b = (
            np.asarray(raw, float)
            - self.baseline
            - np.asarray(currents, float) @ self.feedthrough.T
        )
        a = self.host_pole(Ts)
        out = b.copy()
        cols = np.flatnonzero(self.filtered)
        for k in range(1, b.shape[0]):
            out[k, cols] = a * out[k - 1, cols] + (1 - a) * b[k, cols]
        return out


def _coil_field(model, sensors=None) -> tuple[np.ndarray, np.ndarray]:
    """Return the field without the magnet (p,) and each coil's field per ampere (p, 4)."""
    n_s = model.params.solenoids.count
    x = model.hover_state(0.03)  # any state: the magnet is left out
    base = model.measurement(x, np.zeros(n_s), with_magnet=False)
    raw = np.column_stack(
        [model.measurement(x, np.eye(n_s)[j], with_magnet=False) - base for j in range(n_s)]
    )
    rows = np.arange(base.size)
    if sensors is not None:
        rows = np.concatenate([np.arange(3 * k, 3 * k + 3) for k in sensors])
    return base[rows], raw[rows]


def augment(
    ad: np.ndarray,
    bd: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    filtered: np.ndarray,
    a: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Add the firmware's x/y low-pass to a discrete model ``x+ = Ad x + Bd u, y = C x + D u``.

    The filter state ``f_(k-1)`` of each filtered channel is appended to the
    state; the output of a filtered channel is ``a f_(k-1) + (1 - a)(C x_k + D u_k)``.

    Parameters
    ----------
    ad, bd, c, d : ndarray
        Discrete model, shapes (n, n), (n, m), (p, n), (p, m).
    filtered : ndarray of bool, shape (p,)
        Channels with the low-pass.
    a : float
        Filter pole at the model's sample time.

    Returns
    -------
    tuple of ndarray
        ``Ad, Bd, C, D`` of the augmented model, ``n + (filtered channels)`` states.
    """
    rows = np.flatnonzero(filtered)
    n, q = ad.shape[0], rows.size
    cf, df = c[rows], d[rows]
    ad2 = np.zeros((n + q, n + q))
    ad2[:n, :n] = ad
    ad2[n:, :n] = (1 - a) * cf
    ad2[n:, n:] = a * np.eye(q)
    bd2 = np.vstack([bd, (1 - a) * df])
    c2 = np.hstack([c, np.zeros((c.shape[0], q))])
    d2 = d.copy()
    c2[rows] = np.hstack([(1 - a) * cf, a * np.eye(q)])
    d2[rows] = (1 - a) * df
    return ad2, bd2, c2, d2


def augment_exact(
    A: np.ndarray,
    B: np.ndarray,
    c: np.ndarray,
    d: np.ndarray,
    board: BoardProcessing,
    filtered: np.ndarray,
    Ts: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sample ``dx/dt = A x + B u, b = c x + d u`` with the board's filter, exactly.

    The inputs are held over each host sample; the board filters ``b`` at
    each of its steps (:meth:`BoardProcessing.host_filter`). The filter
    output ``f_k`` of each filtered channel joins the state and is that
    channel's reading (no direct term); unfiltered channels read ``c x + d u``.

    Parameters
    ----------
    A, B : ndarray
        Continuous model, shapes (n, n), (n, m).
    c, d : ndarray
        Processed output (feedthrough removed), shapes (p, n), (p, m).
    board : BoardProcessing
        The board's processing (its weight and period).
    filtered : ndarray of bool, shape (p,)
        Channels with the low-pass.
    Ts : float
        Host sample time, s.

    Returns
    -------
    tuple of ndarray
        ``Ad, Bd, C, D`` of the sampled model, ``n + (filtered channels)`` states.
    """
    from scipy.linalg import expm

    rows = np.flatnonzero(filtered)
    n, m, q = A.shape[0], B.shape[1], rows.size
    fx, fu, a = board.host_filter(A, B, c[rows], d[rows], Ts)
    big = np.zeros((n + m, n + m))
    big[:n, :n], big[:n, n:] = A, B
    e = expm(big * board.board_steps(Ts) * board.board_period)
    ad = np.zeros((n + q, n + q))
    ad[:n, :n] = e[:n, :n]
    ad[n:, :n] = fx
    ad[n:, n:] = a * np.eye(q)
    bd = np.vstack([e[:n, n:], fu])
    c2 = np.hstack([c, np.zeros((c.shape[0], q))])
    d2 = np.array(d, dtype=float)
    c2[rows] = 0.0
    c2[rows, n + np.arange(q)] = 1.0
    d2[rows] = 0.0
    return ad, bd, c2, d2
