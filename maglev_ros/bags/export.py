"""Write data sets as ``.npz``, ``.csv`` or MATLAB ``.mat`` files, and a text summary.

Every file holds one :class:`~maglev_ros.sysid.IdData` and loads back with
:func:`maglev_ros.sysid.load_data` (``maglev-sysid``):

``.npz``
    ``y`` (N, ny), ``u`` (N, nu), ``Ts``, ``t`` (N,), ``DATA`` (ny + nu, N),
    ``output_names``, ``input_names``, ``output_units``, ``input_units``.
``.mat``
    The lab's layout: ``DATA`` with one channel per **row**, outputs first then
    inputs, ``Ts``, ``t`` and ``names`` / ``units`` (cell arrays), ``ny``, ``nu``
    (``maglev-sysid data.mat --rows 1,2 3``).
``.csv``
    A header line ``t [s],<output names>,<input names>`` (a name with a unit as
    ``Bx_0 [T]``) then one row per sample
    (17 significant digits: the doubles round-trip exactly).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .errors import BagError

if TYPE_CHECKING:  # importing maglev_ros.sysid costs seconds (scipy.signal)
    from ..sysid.dataset import IdData

__all__ = ['FORMATS', 'format_summary', 'split_paths', 'write_dataset']

#: File types :func:`write_dataset` writes.
FORMATS = ('.npz', '.csv', '.mat')


def _suffix(path: Path) -> str:
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        raise BagError(f'unknown data file type {suffix or path.name!r} (use .npz, .csv or .mat)')
    return suffix


def split_paths(path: str | Path) -> tuple[Path, Path]:
    """Return the estimation and validation file names next to ``path``.

    Parameters
    ----------
    path : str or Path
        The full data set's file, e.g. ``data.npz``.

    Returns
    -------
    tuple of Path
        ``data_est.npz`` and ``data_val.npz``.
    """
    path = Path(path)
    suffix = _suffix(path)
    return (path.with_name(f'{path.stem}_est{suffix}'), path.with_name(f'{path.stem}_val{suffix}'))


def write_dataset(data: IdData, path: str | Path) -> Path:
    """Write a data set to ``.npz``, ``.csv`` or ``.mat`` (by the file's suffix).

    Parameters
    ----------
    data : IdData
        The data set.
    path : str or Path
        Output file; its directory must exist.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    suffix = _suffix(path)
    if not path.parent.is_dir():
        raise BagError(f'directory {str(path.parent)!r} of {path.name!r} does not exist')
    names = list(data.output_names) + list(data.input_names)
    units = list(data.output_units) + list(data.input_units)
    channels = np.vstack([data.y.T, data.u.T]) if data.nu else np.array(data.y.T)
    t = data.time
    if suffix == '.npz':
        np.savez(
            path,
            y=data.y,
            u=data.u,
            Ts=data.Ts,
            t=t,
            DATA=channels,
            output_names=np.array(data.output_names, dtype=str),
            input_names=np.array(data.input_names, dtype=str),
            output_units=np.array(data.output_units, dtype=str),
            input_units=np.array(data.input_units, dtype=str),
        )
    elif suffix == '.mat':
        from scipy.io import savemat

        def cell(items: list[str]) -> np.ndarray:
            out = np.empty((1, len(items)), dtype=object)
            out[0, :] = items
            return out

        savemat(
            path,
            {
                'DATA': channels,
                'Ts': data.Ts,
                't': t[None, :],
                'names': cell(names),
                'units': cell(units),
                'ny': data.ny,
                'nu': data.nu,
            },
            do_compression=True,
        )
    else:
        bad = [n for n in names if ',' in n or '\n' in n]
        if bad:
            raise BagError(
                f'channel names {bad} contain commas: name them (NAME=SPEC) before writing CSV'
            )
        table = np.column_stack([t, data.y, data.u])
        header = ['t [s]'] + [f'{n} [{u}]' if u else n for n, u in zip(names, units, strict=True)]
        np.savetxt(path, table, delimiter=',', fmt='%.17g', header=','.join(header), comments='')
    return path


def format_summary(summary: dict) -> str:
    """Format a :meth:`BagDataset.summary` as short text.

    Parameters
    ----------
    summary : dict
        The summary.

    Returns
    -------
    str
        A few lines: bag, duration, Ts, samples, channels, topics, gaps, metadata.
    """
    s = summary
    lines = [
        f'bag       {s["bag"]} ({s["storage"]})',
        f'duration  {s["duration_s"]:.6g} s, Ts {s["Ts_s"]:.6g} s '
        f'({1.0 / s["Ts_s"]:.6g} Hz), {s["samples"]} samples',
    ]
    if 'estimation' in s:
        lines.append(
            f'split     estimation {s["estimation"]["samples"]} samples, '
            f'validation {s["validation"]["samples"]} samples'
        )
    for c in s['channels']:
        unit = f' [{c["unit"]}]' if c['unit'] else ''
        name = c['name'] if c['name'] == c['spec'] else f'{c["name"]} = {c["spec"]}'
        lines.append(f'{c["role"]:<9} {name}{unit}')
    for tp in s['topics']:
        dups = f', {tp["duplicates"]} repeated stamps dropped' if tp['duplicates'] else ''
        lines.append(
            f'topic     {tp["topic"]}: {tp["messages"]} messages, {tp["clock"]} '
            f'stamps, {tp["method"]}{dups}'
        )
    trimmed = s['trimmed']
    if trimmed['start'] or trimmed['end']:
        lines.append(
            f'trimmed   {trimmed["start"]} samples at the start, {trimmed["end"]} '
            f'at the end (not every topic had data)'
        )
    if s['gaps']:
        total = sum(g['missing'] for g in s['gaps'])
        count = len(s['gaps'])
        lines.append(
            f'gaps      {count} gap{"s" if count != 1 else ""} ({total} '
            f'sample{"s" if total != 1 else ""}), filled:'
        )
        lines += [
            f'          {g["topic"]}: {g["missing"]} after t = {g["time_s"]:.6f} s ({g["filled"]})'
            for g in s['gaps'][:10]
        ]
        if len(s['gaps']) > 10:
            lines.append(f'          ... {len(s["gaps"]) - 10} more')
    else:
        lines.append('gaps      none')
    for key, value in s['metadata'].items():
        lines.append(f'metadata  {key}: {value}')
    return '\n'.join(lines)
