"""The physics check's reference for a board that processes its field (V4x PC control).

A V4x PC-control board reports its field after removing the power-up
baseline and the coils' feedthrough and after a first-order low-pass on x
and y at its own 5 kHz (:mod:`maglev_ros.physics.board_processing`). An
identified model of such a record (pair current -> Bx or By) is therefore
compared with the linearisation *through the board's processing*:
:func:`board_local_plant` samples it exactly at the board's steps, for a
record whose current of sample k is held until sample k+1 and whose field
of sample k was read before it (what
:class:`~maglev_ros.loop.v4x_pc_plant.V4xPcPlant` records).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..physics.board_processing import BoardProcessing
from .physics_check import PAIRS, LocalPlant, PhysicsCheckError

__all__ = [
    'CANCELLATION',
    'IDENTIFICATION_RATE',
    'board_bag_channels',
    'board_groups',
    'board_local_plant',
    'cancellation_bands',
    'check_board_bag',
    'high_order',
]

#: Hz the loop's record is decimated to before identification (:func:`check_board_bag`).
IDENTIFICATION_RATE = 100.0
#: ``|G_true| / max(|part|)`` below which :func:`cancellation_bands` leaves a frequency out:
#: there a relative error of a part is at least doubled in the compared ratio.
CANCELLATION = 0.5
#: s: the slowest unstable (x, y) mode's time constant of a Maggy (20-35 ms).
SLOWEST_UNSTABLE = 0.035
#: What is left of the mirrored unstable pole's impulse response at the last lag of the
#: high-order ARX (:func:`high_order`).
MIRROR_RESIDUE = 1.0e-4


def high_order(ts: float) -> int:
    """Return the orders (``na = nb``) of the board check's high-order ARX at sample time ``ts``.

    The field a board reports is the plant's response plus the Hall sensors'
    noise, white at the output. For an unstable plant ``B/A`` (``A`` has the
    magnet's pole ``p``, ``|p| > 1``) the one-step predictor of such a record
    is ``A y = B u + A* e``, where ``A*`` has the pole mirrored into the unit
    circle (``1/p``): the ARX form needs ``1/A*``, whose impulse response
    decays as ``|1/p|^k``. The seed's ARX (6-9 lags) has no room for it, and
    its least squares then prefer the stable mirror of the magnet's pole
    itself: the equation error ``A e`` is ``|p|^2`` times smaller with it
    (1.8 at 100 Hz), at the same gain and up to 180 deg of phase off. With
    ``na = nb`` lags enough for ``|1/p|^k`` to fall to
    :data:`MIRROR_RESIDUE` the ARX approximates the predictor and keeps the
    pole (the high-order ARX of Ljung, *System Identification*, 2nd ed.,
    section 10.4; direct closed-loop identification is consistent with a
    noise model that fits, section 13.4).

    Parameters
    ----------
    ts : float
        Sample time of the identification, s.

    Returns
    -------
    int
        ``ceil(ln(1 / MIRROR_RESIDUE) * SLOWEST_UNSTABLE / ts)``: 33 at 100 Hz.
    """
    return math.ceil(math.log(1.0 / MIRROR_RESIDUE) * SLOWEST_UNSTABLE / ts)


def board_groups(ts: float) -> tuple:
    """Return the seed's models, with a high-order ARX (:func:`high_order`) per pair.

    Parameters
    ----------
    ts : float
        Sample time of the identification, s.

    Returns
    -------
    tuple of ModelGroup
        :data:`~maglev_ros.sysid.seed_models.SEED_GROUPS`, each SISO group with
        ``ARX n n 1`` after the seed's models.
    """
    from .seed_models import SEED_GROUPS
    from .workflow import ModelSpec

    n = high_order(ts)
    extra = ModelSpec('arx', {'na': n, 'nb': n, 'nk': 1})
    return tuple(
        dataclasses.replace(g, specs=(*g.specs, extra)) if g.pair else g for g in SEED_GROUPS
    )


def board_local_plant(
    linear,
    Ts: float,
    output: str = 'Bx_0',
    pair: str = 'x',
    board: BoardProcessing | None = None,
) -> LocalPlant:
    """Sample a linearisation through the board's processing into a SISO plant.

    Parameters
    ----------
    linear : physics.LinearModel
        Reduced linearisation with ``outputs`` names (``linearize(model).reduced()``).
    Ts : float
        Host sample time, s (a multiple of the board's 200 us).
    output : str
        A filtered channel (``Bx_<k>`` or ``By_<k>``).
    pair : {'x', 'y'}
        The input: the antisymmetric pair current ``u`` (x+ = u, x- = -u), A.
    board : BoardProcessing
        The board's processing of the linearisation's channels
        (:meth:`BoardProcessing.from_model` of the same model).

    Returns
    -------
    LocalPlant
        State ``[x; f]`` (the magnet's deviation, the filter's output), the
        reading ``y(k) = f(k)``; no delay beyond the model's.

    Raises
    ------
    PhysicsCheckError
        Unknown or unfiltered output, unknown pair, no processing given.
    """
    if board is None:
        raise PhysicsCheckError('board_local_plant needs the board processing (board=...)')
    names = list(getattr(linear, 'outputs', ()) or [])
    if output not in names:
        raise PhysicsCheckError(f'unknown output {output!r}; the model has {names}')
    row = names.index(output)
    if not board.filtered[row]:
        raise PhysicsCheckError(f'{output} is not low-pass filtered by the board (x and y are)')
    if pair not in PAIRS:
        raise PhysicsCheckError(f'unknown pair {pair!r}; choose {", ".join(PAIRS)}')
    if not (np.isfinite(Ts) and Ts > 0):
        raise PhysicsCheckError(f'Ts must be a positive sample time in s, got {Ts!r}')
    A = np.asarray(linear.A, float)
    w = np.zeros(linear.B.shape[1])
    w[:4] = PAIRS[pair]
    b = (np.asarray(linear.B, float) @ w)[:, None]
    c = np.asarray(linear.C, float)[row][None, :]
    d = np.array([[(np.asarray(linear.D, float)[row] - board.feedthrough[row]) @ w]])
    fx, fu, a = board.host_filter(A, b, c, d, Ts)
    from scipy.linalg import expm

    n = A.shape[0]
    big = np.zeros((n + 1, n + 1))
    big[:n, :n], big[:n, n:] = A, b
    e = expm(big * board.board_steps(Ts) * board.board_period)
    A2 = np.zeros((n + 1, n + 1))
    A2[:n, :n] = e[:n, :n]
    A2[n, :n] = fx[0]
    A2[n, n] = a
    B2 = np.concatenate([e[:n, n], fu[0]])
    C2 = np.zeros(n + 1)
    C2[n] = 1.0
    return LocalPlant(A2, B2, C2, 0.0, float(Ts), 0, str(output), w)


def cancellation_bands(
    reference: LocalPlant,
    motion: LocalPlant,
    band: tuple[float, float],
    ratio: float = CANCELLATION,
    n: int = 2000,
) -> list[tuple[float, float]]:
    """Bands (Hz) where the reference is a near-cancellation of its two parts.

    A board's reading of a pair is the magnet's motion (``motion``: the
    reference with the feedthrough removed exactly) plus the direct term the
    firmware's compensation leaves (``reference - motion``). Near the notch
    where they cancel, a relative error of either part (the identified
    model's, or the measured feedthrough's: 0.001-0.005 mT/A) is magnified
    in ``G_id / G_true`` by ``max(|part|) / |G_true|``. Where that exceeds
    ``1 / ratio`` the reference is not known well enough to compare with.

    Parameters
    ----------
    reference : LocalPlant
        :func:`board_local_plant` with the measured pair feedthrough.
    motion : LocalPlant
        The same with the firmware's compensation exact.
    band : (float, float)
        The frequencies looked at, Hz.
    ratio : float
        ``|G_true| / max(|motion|, |direct|)`` below which a frequency is left out.
    n : int
        Log-spaced frequencies looked at.

    Returns
    -------
    list of (float, float)
        Ascending, disjoint.
    """
    f = np.geomspace(band[0], band[1], n)
    g, m = reference.freqresp(f), motion.freqresp(f)
    low = np.abs(g) < ratio * np.maximum(np.abs(m), np.abs(g - m))
    edges = np.flatnonzero(np.diff(np.r_[0, low.astype(int), 0]))
    return [(float(f[a]), float(f[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True)]


def board_bag_channels(sensor: int = 0) -> tuple[list[str], list[str]]:
    """Channel specs of a V4x PC-control loop's bag for the seed's models.

    Outputs ``Bx_0``, ``By_0`` (the board's processed x and y field of its
    sensor, T); inputs ``u_x``, ``u_y`` (the pair currents the board measured
    with the sample's command applied, A) and ``r_x``, ``r_y`` (the
    excitation part of the commands, the IV's instruments, A).

    Parameters
    ----------
    sensor : int
        The parameter set's index of the board's sensor (its topic).
    """
    from ..topics import CURRENTS_TOPIC, EXCITATION_TOPIC, field_channel

    def pair(name: str, topic: str, plus: int) -> str:
        return f'{name}=0.5*{topic}:effort[{plus}]-0.5*{topic}:effort[{plus + 1}]'

    outputs = [f'Bx_0={field_channel(sensor, "x")}', f'By_0={field_channel(sensor, "y")}']
    inputs = [
        pair('u_x', CURRENTS_TOPIC, 0),
        pair('u_y', CURRENTS_TOPIC, 2),
        pair('r_x', EXCITATION_TOPIC, 0),
        pair('r_y', EXCITATION_TOPIC, 2),
    ]
    return outputs, inputs


def check_board_bag(
    bag,
    params: str,
    sensor: int = 0,
    split: float = 0.5,
    band: tuple[float, float] = (1.0, 10.0),
    rate: float | None = IDENTIFICATION_RATE,
):
    """Identify the seed's models and a high-order ARX on a V4x PC-control loop's bag; check them.

    The record is decimated to about ``rate`` first (:meth:`IdData.decimate`: the
    same zero-phase low-pass on inputs, outputs and instruments, which leaves
    their relation unchanged below its cut-off). At the loop's 1 kHz the seed's
    orders (7 9 for x, 6 6 for y) stretch over 0-500 Hz, where above about
    20 Hz the field holds only the filtered sensor noise (with the feedthrough
    removed it sees the coils only through the magnet's motion, which falls as
    1/f^2); an equation-error fit (ARX), weighted towards those frequencies,
    then misses the compared band by 13-44 dB. At 100 Hz the same orders
    describe 0-50 Hz, where the excitation is.

    Parameters
    ----------
    bag : str or Path
        The bag (:func:`~maglev_ros.loop.sample_log.write_sample_bag`).
    params : str
        The parameter set of the reference (the plant's).
    sensor : int
        The board's sensor in the set.
    split : float
        Estimation part of the record.
    band : (float, float)
        Frequencies compared, Hz (default 1-10 Hz: with the feedthrough removed
        the field sees the coils only through the magnet's motion, which falls
        as 1/f^2 above the x mode; at 0.05 A of excitation it is below the
        filtered noise above about 20 Hz).
    rate : float or None
        Samples per second the record is decimated to (by the nearest integer
        factor), Hz; None: the record's own rate.

    Returns
    -------
    data : IdData
        The record (outputs ``Bx_0``, ``By_0``; inputs ``u_x``, ``u_y``, ``r_x``, ``r_y``).
    results : tuple of GroupResult
        :func:`~maglev_ros.sysid.seed_models.identify_groups` of :func:`board_groups`
        (IV with the excitation).
    checks : dict
        :func:`~maglev_ros.sysid.seed_models.physics_deviations` against
        :func:`board_local_plant` of each pair (with the board's pair
        feedthrough of the bag's metadata, ``board_feedthrough``, when the
        loop measured it).
    """
    from ..bags import read_bag
    from ..hardware.v4x_pc_feedthrough import PairFeedthrough
    from ..loop.v4x_pc_setup import board_model
    from ..physics import linearize
    from .seed_models import identify_groups, physics_deviations

    outputs, inputs = board_bag_channels(sensor)
    # periods the host missed are gaps: outputs interpolated, inputs held across them
    dataset = read_bag(bag, outputs, inputs, allow_gaps=True)
    data = dataset.data
    # the reference: the loop's own sampling (decimation keeps that relation, filtered)
    loop_ts = data.Ts
    if rate is not None:
        if not rate > 0:
            raise ValueError(f'rate must be a positive number of Hz, got {rate!r}')
        data = data.decimate(max(1, round(1.0 / (data.Ts * rate))))
    model = board_model(params, sensor)
    linear = linearize(model).reduced()
    # the board's pair feedthrough as the loop measured it before the magnet came, if it did
    recorded = dataset.metadata.get('board_feedthrough')
    pairs = None if recorded is None else PairFeedthrough.response_from(recorded)
    board = BoardProcessing.from_model(model, pairs=pairs)
    results = identify_groups(data, split, board_groups(data.Ts))
    plants = {p: board_local_plant(linear, loop_ts, f'B{p}_0', p, board) for p in ('x', 'y')}
    uncertain = {}
    if pairs is not None:  # the direct term the firmware left: notches where it cancels
        exact = BoardProcessing.from_model(model)
        uncertain = {
            p: cancellation_bands(
                plants[p], board_local_plant(linear, loop_ts, f'B{p}_0', p, exact), band
            )
            for p in ('x', 'y')
        }
    return data, results, physics_deviations(results, plants, band, uncertain)
