"""Read identification data from ``.npz``, ``.csv`` and MATLAB ``.mat`` files.

Accepted layouts:

* ``y`` (N, ny) and ``u`` (N, nu) arrays (npz/mat variables), optional ``Ts``;
* a channel matrix (default name ``DATA``, as the lab's ``data.mat``) with one
  channel per **row** (or per column if it has more rows than columns), from
  which ``rows=(outputs, inputs)`` picks channels counted from 1 as in MATLAB;
* CSV with a header line: columns named in ``outputs``/``inputs`` (default:
  names starting with ``y`` are outputs, with ``u`` inputs); a ``t``/``time``
  column gives ``Ts`` if it is not passed.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from .dataset import IdData

__all__ = ['DataFileError', 'load_data']


class DataFileError(ValueError):
    """A data file that is missing, unreadable or lacks the requested variables."""


def _pick_rows(
    matrix: np.ndarray, rows: tuple[Sequence[int], Sequence[int]], name: str
) -> tuple[np.ndarray, np.ndarray]:
    m = np.asarray(matrix, dtype=float)
    if m.ndim != 2:
        raise DataFileError(f'variable {name!r} must be a 2-D matrix, got shape {m.shape}')
    channels = m if m.shape[0] <= m.shape[1] else m.T
    outs, ins = ([int(r) for r in rows[0]], [int(r) for r in rows[1]])
    for r in outs + ins:
        if not 1 <= r <= channels.shape[0]:
            raise DataFileError(
                f'row {r} out of range: {name!r} has {channels.shape[0]} '
                f'channels (rows are counted from 1)'
            )
    return channels[[r - 1 for r in outs]].T, channels[[r - 1 for r in ins]].T


def _from_mapping(
    variables: dict, path: Path, rows: tuple | None, matrix: str, Ts: float | None
) -> tuple[np.ndarray, np.ndarray, float | None]:
    file_ts = variables.get('Ts')
    if file_ts is not None:
        file_ts = float(np.asarray(file_ts).ravel()[0])
    if rows is not None or ('y' not in variables and matrix in variables):
        if matrix not in variables:
            names = sorted(k for k in variables if not k.startswith('__'))
            raise DataFileError(f'{path.name} has no variable {matrix!r} (variables: {names})')
        if rows is None:
            raise DataFileError(
                f'{path.name}: choose output and input rows of {matrix!r} '
                f'with rows=(outputs, inputs) / --rows'
            )
        y, u = _pick_rows(variables[matrix], rows, matrix)
    else:
        missing = [k for k in ('y', 'u') if k not in variables]
        if missing:
            raise DataFileError(
                f'{path.name} has no variable {missing[0]!r} (expected y and u, '
                f'or a {matrix!r} matrix with rows)'
            )
        y, u = np.asarray(variables['y'], dtype=float), np.asarray(variables['u'], dtype=float)
        if y.ndim == 2 and y.shape[0] < y.shape[1] and y.shape[0] <= 8:
            y = y.T
        if u.ndim == 2 and u.shape[0] < u.shape[1] and u.shape[0] <= 8:
            u = u.T
    return y, u, (Ts if Ts is not None else file_ts)


def _read_csv(
    path: Path, outputs: Sequence[str] | None, inputs: Sequence[str] | None
) -> tuple[np.ndarray, np.ndarray, float | None, list[str], list[str]]:
    with path.open() as fh:
        header = [h.strip() for h in fh.readline().strip().split(',')]
    try:
        table = np.loadtxt(path, delimiter=',', skiprows=1, ndmin=2)
    except ValueError as exc:
        raise DataFileError(
            f'{path.name} is not a numeric CSV with one header line: {exc}'
        ) from None
    if table.shape[1] != len(header):
        raise DataFileError(
            f'{path.name}: header has {len(header)} names but rows have {table.shape[1]} values'
        )
    outputs = list(outputs) if outputs else [h for h in header if h.lower().startswith('y')]
    inputs = list(inputs) if inputs else [h for h in header if h.lower().startswith('u')]
    for name in outputs + inputs:
        if name not in header:
            raise DataFileError(f'{path.name} has no column {name!r} (columns: {header})')
    if not outputs:
        raise DataFileError(f'{path.name}: no output columns (name them y..., or pass outputs)')
    col = {h: i for i, h in enumerate(header)}
    Ts = None
    for tname in ('t', 'time'):
        if tname in col and table.shape[0] > 1:
            Ts = float(np.median(np.diff(table[:, col[tname]])))
    return (
        table[:, [col[n] for n in outputs]],
        table[:, [col[n] for n in inputs]],
        Ts,
        outputs,
        inputs,
    )


def load_data(
    path: str | Path,
    Ts: float | None = None,
    rows: tuple[Sequence[int], Sequence[int]] | None = None,
    matrix: str = 'DATA',
    outputs: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    output_units: Sequence[str] | None = None,
    input_units: Sequence[str] | None = None,
) -> IdData:
    """Load an :class:`IdData` from a ``.npz``, ``.csv`` or ``.mat`` file.

    Parameters
    ----------
    path : str or Path
        Data file.
    Ts : float, optional
        Sample time in seconds (overrides a ``Ts`` stored in the file).
    rows : (sequence of int, sequence of int), optional
        Output and input rows of the channel matrix, counted from 1.
    matrix : str
        Name of the channel-matrix variable (default ``'DATA'``).
    outputs, inputs : sequence of str, optional
        CSV column names (also used as channel names).
    output_units, input_units : sequence of str, optional
        Channel units.

    Returns
    -------
    IdData
        The data set.

    Raises
    ------
    DataFileError
        Missing file or variable, MATLAB v7.3 file, unknown format, no ``Ts``.
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f'data file {str(path)!r} does not exist')
    suffix = path.suffix.lower()
    names_y = names_u = None
    if suffix == '.npz':
        with np.load(path, allow_pickle=False) as npz:
            variables = {k: npz[k] for k in npz.files}
        y, u, Ts = _from_mapping(variables, path, rows, matrix, Ts)
    elif suffix == '.mat':
        from scipy.io import loadmat

        try:
            variables = loadmat(path)
        except NotImplementedError:
            raise DataFileError(
                f'{path.name} is a MATLAB v7.3 (HDF5) file; save it in the older format '
                f"in MATLAB with save('{path.name}', 'DATA', '-v7') and retry"
            ) from None
        except ValueError as exc:
            raise DataFileError(f'{path.name} is not a readable MATLAB file: {exc}') from None
        y, u, Ts = _from_mapping(variables, path, rows, matrix, Ts)
    elif suffix == '.csv':
        y, u, csv_ts, names_y, names_u = _read_csv(path, outputs, inputs)
        Ts = Ts if Ts is not None else csv_ts
    else:
        raise DataFileError(
            f'unknown data file type {suffix!r} of {path.name} (use .npz, .csv or .mat)'
        )
    if Ts is None:
        raise DataFileError(f'{path.name} stores no sample time: pass Ts (--ts SECONDS)')
    if outputs and names_y is None:
        names_y = list(outputs)
    if inputs and names_u is None:
        names_u = list(inputs)
    try:
        return IdData(y, u, Ts, names_y, names_u, output_units, input_units)
    except ValueError as exc:
        raise DataFileError(f'{path.name}: {exc}') from None
