"""A study's rows: the journal written as runs finish, the table, and the summary.

The journal (``runs.jsonl``, one JSON object per finished run, flushed at
once) is what an interrupted study keeps and ``--resume`` reads. The table
(``results.parquet`` when pyarrow is installed, ``results.csv`` otherwise)
has one row per run in run order. Floats are written exactly (JSON and CSV
with Python's shortest round-trip repr, Parquet as float64), so equal runs
give equal files.
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from .runner import METRICS, OUTCOMES

__all__ = [
    'Journal',
    'columns',
    'read_table',
    'summary',
    'table_format',
    'write_table',
    'wilson_interval',
]


class Journal:
    """Append-only record of finished runs.

    Parameters
    ----------
    path : Path
        The ``runs.jsonl`` file.
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    def read(self) -> dict[int, dict[str, Any]]:
        """Rows by run index (a line cut short by a kill is ignored)."""
        rows: dict[int, dict[str, Any]] = {}
        if not self.path.exists():
            return rows
        with open(self.path, encoding='utf-8') as stream:
            for line in stream:
                if not line.endswith('\n'):
                    break  # the last line, cut short
                row = json.loads(line)
                rows[int(row['run'])] = row
        return rows

    def append(self, row: dict[str, Any]) -> None:
        """Add a finished run and flush it to disk.

        Parameters
        ----------
        row : dict
        """
        with open(self.path, 'a', encoding='utf-8') as stream:
            stream.write(json.dumps(row) + '\n')
            stream.flush()
            os.fsync(stream.fileno())


def columns(keys: Sequence[str]) -> list[str]:
    """Table columns: run, seed, the study's parameters, the metrics.

    Parameters
    ----------
    keys : sequence of str
        The study's parameters, in order.
    """
    return ['run', 'seed', *keys, *METRICS]


def table_format() -> str:
    """``'parquet'`` when pyarrow can be imported, else ``'csv'``."""
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return 'csv'
    return 'parquet'


def write_table(
    rows: Iterable[dict[str, Any]],
    cols: Sequence[str],
    stem: str | os.PathLike,
    fmt: str | None = None,
) -> Path:
    """Write rows sorted by run; return the file (``stem`` + ``.parquet`` or ``.csv``).

    Parameters
    ----------
    rows : iterable of dict
    cols : sequence of str
        Column order.
    stem : path
        File name without suffix.
    fmt : {'parquet', 'csv'}, optional
        Default: :func:`table_format`.
    """
    fmt = fmt or table_format()
    ordered = sorted(rows, key=lambda r: r['run'])
    path = Path(f'{os.fspath(stem)}.{fmt}')
    tmp = path.with_name(path.name + '.tmp')
    if fmt == 'parquet':
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.table({c: [r[c] for r in ordered] for c in cols})
        pq.write_table(table, tmp)
    else:
        with open(tmp, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.writer(stream)
            writer.writerow(cols)
            for r in ordered:
                writer.writerow([repr(r[c]) if isinstance(r[c], float) else r[c] for c in cols])
    os.replace(tmp, path)
    return path


def _parse(text: str) -> Any:
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return {'True': True, 'False': False}.get(text, text)


def read_table(path: str | os.PathLike) -> list[dict[str, Any]]:
    """Read a table written by :func:`write_table` back into rows.

    Parameters
    ----------
    path : path
        A ``.parquet`` or ``.csv`` file.
    """
    path = Path(path)
    if path.suffix == '.parquet':
        import pyarrow.parquet as pq

        return pq.read_table(path).to_pylist()
    with open(path, newline='', encoding='utf-8') as stream:
        return [{k: _parse(v) for k, v in row.items()} for row in csv.DictReader(stream)]


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % (z = 1.96) Wilson score interval of a success rate.

    Parameters
    ----------
    successes, n : int
    z : float
    """
    if n == 0:
        return (0.0, 1.0)
    p = successes / n
    denom = 1 + z**2 / n
    centre = (p + z**2 / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z**2 / (4 * n**2)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def summary(rows: Sequence[dict[str, Any]], varied: Sequence[str], total: int) -> str:
    """Text summary: success rate, outcomes, success rate per value of each grid parameter.

    Parameters
    ----------
    rows : sequence of dict
    varied : sequence of str
        Grid parameters to break the rate down by.
    total : int
        Runs in the study (more than ``len(rows)`` when it was interrupted).
    """
    n = len(rows)
    ok = sum(bool(r['success']) for r in rows)
    lines = [f'{n} of {total} runs done; success {ok}/{n} ({100 * ok / max(n, 1):.1f} %)']
    counts = Counter(r['outcome'] for r in rows)
    lines.append('outcomes: ' + ', '.join(f'{o} {counts[o]}' for o in OUTCOMES if counts[o]))
    for key in varied:
        groups: dict[Any, list[bool]] = defaultdict(list)
        for r in rows:
            groups[r[key]].append(bool(r['success']))
        parts = [f'{v:g}' if isinstance(v, float) else str(v) for v in groups]
        rates = [
            f'{p}: {100 * sum(s) / len(s):.0f} %'
            for p, s in zip(parts, groups.values(), strict=True)
        ]
        if len(rates) > 12:
            rates = rates[:6] + ['...'] + rates[-5:]
        lines.append(f'{key}: ' + ', '.join(rates))
    errors = [r for r in rows if r['outcome'] == 'error']
    if errors:
        lines.append(f'run {errors[0]["run"]} could not be built: {errors[0]["reason"]}')
    return '\n'.join(lines)
