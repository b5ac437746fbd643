"""Read identification data from ``.npz``, ``.csv`` and MATLAB ``.mat`` files.

Accepted layouts:

* ``y`` (N, ny) and ``u`` (N, nu) arrays (npz/mat variables), optional ``Ts``;
* a channel matrix (default name ``DATA``, as the lab's ``data.mat``) with one
  channel per **row** (or per column if it has more rows than columns), from
  which ``rows=(outputs, inputs)`` picks channels counted from 1 as in MATLAB;
* CSV with a header line: columns named in ``outputs``/``inputs`` (default:
  names starting with ``y`` are outputs, with ``u`` inputs); a ``t``/``time``
  column gives ``Ts`` if it is not passed. A header name may carry its unit in
  brackets, ``Bx_0 [T]``.

Names, units and time travel with the data (``maglev-bag2data`` writes them):

* npz: ``output_names``, ``input_names``, ``output_units``, ``input_units``
  string arrays; mat: ``names`` and ``units`` cell arrays over the rows of
  ``DATA`` (outputs first) with ``ny``/``nu`` (then ``rows`` may be left out:
  the first ``ny`` rows are the outputs, the next ``nu`` the inputs);
* a time vector ``t`` (npz/mat variable, CSV column ``t``/``time``) in
  seconds gives ``Ts`` and the first sample's time, and is checked: time that
  runs backwards, a gap (a step above 1.5 ``Ts``) or non-uniform sampling
  (steps more than 10 % off ``Ts``) is one clear error.  With
  ``allow_gaps=True`` a record with gaps is cut at them and the longest
  gap-free piece is kept (the pieces left out are reported in ``notes``);
  backwards time and jitter are never repaired.
"""

from __future__ import annotations

import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from .dataset import IdData

__all__ = ['DataFileError', 'check_time', 'load_data']


class DataFileError(ValueError):
    """A data file that is missing, unreadable or lacks the requested variables."""


GAP_FACTOR = 1.5  # a time step above this many Ts is a gap
JITTER = 0.1  # steps more than this fraction off Ts are non-uniform sampling


def _strings(value: object) -> list[str] | None:
    """Names stored in a file: a string array (npz) or a cell array (mat); None if absent."""
    if value is None:
        return None
    array = np.asarray(value, dtype=object).ravel()
    out = []
    for item in array:
        item = np.asarray(item).ravel()
        out.append(str(item[0]) if item.size else '')
    return out


def check_time(t: np.ndarray, name: str) -> tuple[float, list[slice]]:
    """Check a time vector and return its sample time and its gap-free pieces.

    Parameters
    ----------
    t : ndarray, shape (N,)
        Sample instants in seconds.
    name : str
        The file's name, for messages.

    Returns
    -------
    Ts : float
        The median step in seconds.
    pieces : list of slice
        The gap-free pieces (one if there is no gap).

    Raises
    ------
    DataFileError
        Time that runs backwards or stands still, or non-uniform sampling.
    """
    t = np.asarray(t, dtype=float).ravel()
    if t.size < 2:
        return float('nan'), [slice(0, t.size)]
    if not np.all(np.isfinite(t)):
        raise DataFileError(f'{name}: the time vector has NaN or infinite values')
    step = np.diff(t)
    back = np.flatnonzero(step <= 0)
    if back.size:
        k = int(back[0])
        raise DataFileError(
            f'{name}: time runs backwards or stands still at sample {k + 2} '
            f'(t = {t[k + 1]:.6g} s after {t[k]:.6g} s, {back.size} such step(s)): sort '
            'the file by time or cut it there (a restarted recording is two experiments)'
        )
    median = float(np.median(step))
    gap = step > GAP_FACTOR * median
    odd = (np.abs(step - median) > JITTER * median) & ~gap
    if odd.any():
        k = int(np.flatnonzero(odd)[0])
        raise DataFileError(
            f'{name}: the sampling is not uniform: the step at t = {t[k]:.6g} s is '
            f'{step[k]:.6g} s against a median of {median:.6g} s ({int(odd.sum())} steps '
            f'off by more than {100 * JITTER:.0f} %): resample the record onto a uniform '
            'time base first (maglev-bag2data does for bags)'
        )
    cuts = np.flatnonzero(gap) + 1
    bounds = [0, *cuts.tolist(), t.size]
    return median, [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]


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


def _from_mapping(variables: dict, path: Path, rows: tuple | None, matrix: str) -> dict:
    """Channels, names, units, time and ``Ts`` of npz/mat variables."""
    out: dict = {'Ts': None, 't': None, 'names': (None, None), 'units': (None, None)}
    file_ts = variables.get('Ts')
    if file_ts is not None:
        out['Ts'] = float(np.asarray(file_ts).ravel()[0])
    if 't' in variables:
        out['t'] = np.asarray(variables['t'], dtype=float).ravel()
    names, units = _strings(variables.get('names')), _strings(variables.get('units'))
    stored = [
        int(np.asarray(variables[k]).ravel()[0]) if k in variables else None for k in ('ny', 'nu')
    ]
    if rows is None and 'y' not in variables and matrix in variables and None not in stored:
        rows = (range(1, stored[0] + 1), range(stored[0] + 1, stored[0] + stored[1] + 1))
    if rows is not None or ('y' not in variables and matrix in variables):
        if matrix not in variables:
            found = sorted(k for k in variables if not k.startswith('__'))
            raise DataFileError(f'{path.name} has no variable {matrix!r} (variables: {found})')
        if rows is None:
            raise DataFileError(
                f'{path.name}: choose output and input rows of {matrix!r} '
                f'with rows=(outputs, inputs) / --rows'
            )
        out['y'], out['u'] = _pick_rows(variables[matrix], rows, matrix)
        picked = [[int(r) - 1 for r in rows[0]], [int(r) - 1 for r in rows[1]]]
        count = len(names) if names is not None else -1
        if names is not None and all(r < count for r in picked[0] + picked[1]):
            out['names'] = tuple([names[r] for r in part] for part in picked)
        if units is not None and all(r < len(units) for r in picked[0] + picked[1]):
            out['units'] = tuple([units[r] for r in part] for part in picked)
        return out
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
    out['y'], out['u'] = y, u
    out['names'] = (
        _strings(variables.get('output_names')),
        _strings(variables.get('input_names')),
    )
    out['units'] = (
        _strings(variables.get('output_units')),
        _strings(variables.get('input_units')),
    )
    return out


def _name_and_unit(header: str) -> tuple[str, str]:
    """Split ``'Bx_0 [T]'`` into ``('Bx_0', 'T')``; a name without brackets has no unit."""
    text = header.strip()
    if text.endswith(']') and '[' in text:
        name, _, unit = text[:-1].rpartition('[')
        return name.strip(), unit.strip()
    return text, ''


def _read_csv(path: Path, outputs: Sequence[str] | None, inputs: Sequence[str] | None) -> dict:
    with path.open() as fh:
        first = fh.readline()
        has_rows = any(line.strip() for line in fh)
    if not first.strip():
        raise DataFileError(f'{path.name} is empty: expected a header line and rows of numbers')
    if not has_rows:
        raise DataFileError(f'{path.name} has a header line but no rows of numbers')
    header = [_name_and_unit(h) for h in first.strip().split(',')]
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
    names = [n for n, _ in header]
    unit_of = dict(header)
    outputs = list(outputs) if outputs else [h for h in names if h.lower().startswith('y')]
    inputs = list(inputs) if inputs else [h for h in names if h.lower().startswith('u')]
    for name in outputs + inputs:
        if name not in names:
            raise DataFileError(f'{path.name} has no column {name!r} (columns: {names})')
    if not outputs:
        raise DataFileError(f'{path.name}: no output columns (name them y..., or pass outputs)')
    col = {h: i for i, h in enumerate(names)}
    t = None
    for tname in ('t', 'time'):
        if tname in col:
            t = table[:, col[tname]]
            break
    return {
        'y': table[:, [col[n] for n in outputs]],
        'u': table[:, [col[n] for n in inputs]],
        'Ts': None,
        't': t,
        'names': (outputs, inputs),
        'units': ([unit_of[n] for n in outputs], [unit_of[n] for n in inputs]),
    }


def load_data(
    path: str | Path,
    Ts: float | None = None,
    rows: tuple[Sequence[int], Sequence[int]] | None = None,
    matrix: str = 'DATA',
    outputs: Sequence[str] | None = None,
    inputs: Sequence[str] | None = None,
    output_units: Sequence[str] | None = None,
    input_units: Sequence[str] | None = None,
    allow_gaps: bool = False,
    notes: list[str] | None = None,
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
        Channel units (default: the file's, if it stores them).
    allow_gaps : bool
        Keep the longest gap-free piece of a record whose time vector has gaps
        instead of refusing it.
    notes : list of str, optional
        Receives a line about what ``allow_gaps`` left out.

    Returns
    -------
    IdData
        The data set.

    Raises
    ------
    DataFileError
        Missing file or variable, MATLAB v7.3 file, unknown format, no ``Ts``;
        a time vector that runs backwards, has gaps (unless ``allow_gaps``) or
        is not uniform.
    """
    path = Path(path)
    if not path.is_file():
        raise DataFileError(f'data file {str(path)!r} does not exist')
    suffix = path.suffix.lower()
    if suffix == '.npz':
        if path.stat().st_size == 0:
            raise DataFileError(f'{path.name} is empty (0 bytes): write the data again')
        try:
            npz = np.load(path, allow_pickle=False)
        except (EOFError, ValueError, zipfile.BadZipFile):
            raise DataFileError(
                f'{path.name} is not a readable .npz archive: write it with '
                'numpy.savez(path, y=..., u=..., Ts=...)'
            ) from None
        if not isinstance(npz, Mapping):
            raise DataFileError(
                f'{path.name} holds one array, not named variables: save it with '
                'numpy.savez(path, y=..., u=..., Ts=...)'
            )
        with npz:
            variables = {k: npz[k] for k in npz.files}
        found = _from_mapping(variables, path, rows, matrix)
    elif suffix == '.mat':
        from scipy.io import loadmat
        from scipy.io.matlab import MatReadError

        if path.stat().st_size == 0:
            raise DataFileError(f'{path.name} is empty (0 bytes): write the data again')
        try:
            variables = loadmat(path)
        except (MatReadError, TypeError) as exc:  # scipy says TypeError for a bad record
            raise DataFileError(f'{path.name} is not a readable MATLAB file: {exc}') from None
        except NotImplementedError:
            raise DataFileError(
                f'{path.name} is a MATLAB v7.3 (HDF5) file; save it in the older format '
                f"in MATLAB with save('{path.name}', 'DATA', '-v7') and retry"
            ) from None
        except ValueError as exc:
            raise DataFileError(f'{path.name} is not a readable MATLAB file: {exc}') from None
        found = _from_mapping(variables, path, rows, matrix)
    elif suffix == '.csv':
        found = _read_csv(path, outputs, inputs)
    else:
        raise DataFileError(
            f'unknown data file type {suffix!r} of {path.name} (use .npz, .csv or .mat)'
        )
    y, u, t = found['y'], found['u'], found['t']
    t0 = 0.0
    if t is not None and t.size != np.shape(y)[0]:
        raise DataFileError(
            f'{path.name}: the time vector t has {t.size} samples, the channels {np.shape(y)[0]}'
        )
    if t is not None and t.size > 1:
        step, pieces = check_time(t, path.name)
        if len(pieces) > 1:
            gaps = [(t[p.start - 1], t[p.start]) for p in pieces[1:]]
            shown = ', '.join(f'{b - a:.3g} s at t = {a:.6g} s' for a, b in gaps[:3])
            if not allow_gaps:
                raise DataFileError(
                    f'{path.name}: the time vector has {len(gaps)} gap(s) ({shown}'
                    f'{", ..." if len(gaps) > 3 else ""}; Ts {step:.6g} s): cut the record '
                    'there, or pass --allow-gaps to keep its longest gap-free piece'
                )
            keep = max(pieces, key=lambda p: p.stop - p.start)
            if notes is not None:
                notes.append(
                    f'{path.name}: {len(gaps)} gap(s) in the time vector ({shown}); kept the '
                    f'longest gap-free piece, samples {keep.start + 1}-{keep.stop} of {t.size} '
                    f'(t = {t[keep.start]:.6g}..{t[keep.stop - 1]:.6g} s)'
                )
            y, u, t = np.asarray(y)[keep], np.asarray(u)[keep], t[keep]
        if Ts is not None and abs(Ts - step) > 0.01 * step and notes is not None:
            notes.append(
                f'{path.name}: the given sample time {Ts:g} s overrides the time vector '
                f'(step {step:.6g} s)'
            )
        stored = found['Ts']
        if Ts is None and stored is not None and abs(stored - step) <= 0.01 * step:
            Ts = stored  # the exact value the writer stored, not the time vector's rounding
        Ts = step if Ts is None else Ts
        t0 = float(t[0])
    Ts = Ts if Ts is not None else found['Ts']
    if Ts is None:
        raise DataFileError(f'{path.name} stores no sample time: pass Ts (--ts SECONDS)')
    names_y, names_u = found['names']
    units_y, units_u = found['units']
    names_y = list(outputs) if outputs and names_y is None else names_y
    names_u = list(inputs) if inputs and names_u is None else names_u
    units_y = units_y if output_units is None else list(output_units)
    units_u = units_u if input_units is None else list(input_units)
    try:
        return IdData(y, u, Ts, names_y, names_u, units_y, units_u, t0=t0)
    except ValueError as exc:
        raise DataFileError(f'{path.name}: {exc}') from None
