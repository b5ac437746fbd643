"""The seed's models of the lab report, identified on one closed-loop record, ROS-free.

The lab's report identifies, on the x and y field of the sensor under the
magnet against the antisymmetric pair inputs ``u_x``, ``u_y``:

* x: ARX and IV 7 9 1, ARMAX 5 5 3 1 (``Bx_0`` against ``u_x``);
* y: ARX and IV 6 6 1, ARMAX 6 6 5 1 (``By_0`` against ``u_y``);
* MIMO 2x2: ARX ``na [4 4; 0 4]``, ``nb [2 2; 0 2]`` and ARMAX
  ``na [2 2; 0 2]``, ``nb [1 1; 0 1]``, ``nc [1; 1]`` (``nk`` 1).

:data:`SEED_GROUPS` holds them (the README's ``maglev-sysid`` commands and
``mimo.yaml``); :func:`identify_groups` fits and validates them with the
workflow of ``maglev-sysid`` (:func:`~.workflow.identify`: one row per model,
none lost), each SISO IV with its pair's excitation as the instruments
(closed-loop data: the excitation is not correlated with the noise), and
:func:`physics_deviations` compares every SISO model's frequency response
with the linearisation (:mod:`.physics_check`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .dataset import IdData
from .physics_check import FrequencyDeviation, PhysicsCheckError, compare_response
from .workflow import Identification, ModelSpec, identify

__all__ = [
    'SEED_GROUPS',
    'GroupResult',
    'ModelGroup',
    'identify_groups',
    'physics_deviations',
]


@dataclass(frozen=True)
class ModelGroup:
    """Models identified on the same channels.

    Attributes
    ----------
    name : str
        ``x``, ``y`` or ``mimo``.
    outputs, inputs : tuple of str
        Channel names of the data set.
    specs : tuple of ModelSpec
        Structures and orders.
    instruments : tuple of str
        Instrument channels of the IV models (the excitation of each input),
        empty for none.
    pair : str
        The SISO input's coil pair for the physics check (``x``, ``y``;
        empty for MIMO).
    """

    name: str
    outputs: tuple[str, ...]
    inputs: tuple[str, ...]
    specs: tuple[ModelSpec, ...]
    instruments: tuple[str, ...] = ()
    pair: str = ''


#: The seed's models (the lab report's): x and y SISO, the 2x2 MIMO.
SEED_GROUPS: tuple[ModelGroup, ...] = (
    ModelGroup(
        'x',
        ('Bx_0',),
        ('u_x',),
        (
            ModelSpec('arx', {'na': 7, 'nb': 9, 'nk': 1}),
            ModelSpec('iv', {'na': 7, 'nb': 9, 'nk': 1}),
            ModelSpec('armax', {'na': 5, 'nb': 5, 'nc': 3, 'nk': 1}),
        ),
        ('r_x',),
        'x',
    ),
    ModelGroup(
        'y',
        ('By_0',),
        ('u_y',),
        (
            ModelSpec('arx', {'na': 6, 'nb': 6, 'nk': 1}),
            ModelSpec('iv', {'na': 6, 'nb': 6, 'nk': 1}),
            ModelSpec('armax', {'na': 6, 'nb': 6, 'nc': 5, 'nk': 1}),
        ),
        ('r_y',),
        'y',
    ),
    ModelGroup(
        'mimo',
        ('Bx_0', 'By_0'),
        ('u_x', 'u_y'),
        (
            ModelSpec(
                'arx',
                {'na': [[4, 4], [0, 4]], 'nb': [[2, 2], [0, 2]], 'nk': [[1, 1], [1, 1]]},
            ),
            ModelSpec(
                'armax',
                {'na': [[2, 2], [0, 2]], 'nb': [[1, 1], [0, 1]], 'nc': [1, 1], 'nk': 1},
            ),
        ),
    ),
)


@dataclass(frozen=True)
class GroupResult:
    """The identification of one group.

    Attributes
    ----------
    group : ModelGroup
    result : Identification
        One row per spec (status, fits, models), the data halves.
    instruments : tuple of str
        The instruments the IV rows used (empty: the input-based ``iv4``).
    """

    group: ModelGroup
    result: Identification
    instruments: tuple[str, ...] = ()


def _select(data: IdData, outputs: Sequence[str], inputs: Sequence[str]) -> IdData:
    """Return the named channels of ``data`` (a missing name is a ValueError)."""
    try:
        o = [data.output_names.index(name) for name in outputs]
        i = [data.input_names.index(name) for name in inputs]
    except ValueError:
        raise ValueError(
            f'the data have outputs {data.output_names} and inputs {data.input_names}; '
            f'need {list(outputs)} and {list(inputs)}'
        ) from None
    return data.select(o, i)


def identify_groups(
    data: IdData,
    split: float | int = 0.5,
    groups: Sequence[ModelGroup] = SEED_GROUPS,
    use_instruments: bool = True,
    progress: Callable[[str, int, float], None] | None = None,
) -> tuple[GroupResult, ...]:
    """Detrend, split and identify every group's models (none lost).

    Parameters
    ----------
    data : IdData
        Outputs and inputs the groups name; the instrument channels (e.g.
        ``r_x``) as further inputs.
    split : float or int
        Estimation part: fraction or sample count (the rest validates).
    groups : sequence of ModelGroup
        Default: the seed's models.
    use_instruments : bool
        IV with the group's instruments (default); False: the input-based
        ``iv4`` (biased on closed-loop data).
    progress : callable, optional
        ``(label, step, loss)`` as :func:`~.workflow.identify` calls it, the
        label prefixed with the group's name.

    Returns
    -------
    tuple of GroupResult
        In the order of ``groups``.

    Raises
    ------
    ValueError
        A channel a group names is missing.
    """
    est_all, val_all = data.detrend().split(split)
    results = []
    for group in groups:
        est = _select(est_all, group.outputs, group.inputs)
        val = _select(val_all, group.outputs, group.inputs)
        z = z_val = None
        used: tuple[str, ...] = ()
        if use_instruments and group.instruments:
            z = np.asarray(_select(est_all, group.outputs, group.instruments).u)
            z_val = np.asarray(_select(val_all, group.outputs, group.instruments).u)
            used = group.instruments
        step = None
        if progress is not None:
            step = _prefixed(progress, group.name)
        result = identify(
            est, val, group.specs, progress=step, instruments=z, validation_instruments=z_val
        )
        results.append(GroupResult(group, result, used))
    return tuple(results)


def _prefixed(progress, name: str):
    return lambda label, step, loss: progress(f'{name}: {label}', step, loss)


def physics_deviations(
    results: Sequence[GroupResult],
    plants: dict,
    band: tuple[float, float],
    uncertain: dict | None = None,
) -> dict[tuple[str, str], FrequencyDeviation | str]:
    """Compare each SISO model with the true local transfer function of its pair.

    Parameters
    ----------
    results : sequence of GroupResult
        From :func:`identify_groups`.
    plants : dict
        Pair name (``x``, ``y``) to its :class:`~.physics_check.LocalPlant`.
    band : (float, float)
        Frequencies compared, Hz (the excited band).
    uncertain : dict, optional
        Pair name to the bands (Hz) where its reference is uncertain
        (:func:`~.physics_check.compare_response`'s ``uncertain``).

    Returns
    -------
    dict
        ``(group name, row label)`` to the deviation, or to the reason there
        is none (the model failed; the check refused).
    """
    out: dict[tuple[str, str], FrequencyDeviation | str] = {}
    for item in results:
        pair = item.group.pair
        if not pair or pair not in plants:
            continue
        for row in item.result.rows:
            key = (item.group.name, row.label)
            if row.model is None:
                out[key] = f'no model ({row.status})'
                continue
            try:
                out[key] = compare_response(
                    row.model, plants[pair], band, uncertain=(uncertain or {}).get(pair, ())
                )
            except PhysicsCheckError as err:
                out[key] = str(err)
    return out
