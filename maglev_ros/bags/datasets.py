"""Bag -> identification data set (:class:`maglev_ros.sysid.IdData`).

:func:`read_bag` reads the channels (see :mod:`~maglev_ros.bags.channels`) of
a rosbag2 bag, aligns them on one uniform time base (the rule and the gap
policy are in :mod:`~maglev_ros.bags.alignment`) and returns a
:class:`BagDataset`: the :class:`~maglev_ros.sysid.IdData` (outputs ``y``,
inputs ``u``, ``Ts``, names, units) with how it was made (alignment per topic,
gaps, trimmed samples, run metadata).  :func:`load_bag_dataset` returns just
the ``IdData``, for ``maglev-sysid``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .alignment import TOLERANCE, Alignment, Gap, Source, align
from .channels import Channel, FieldRef, parse_channel, unit_of
from .errors import BagError
from .extraction import read_topics
from .reader import BagReader

if TYPE_CHECKING:  # importing maglev_ros.sysid costs seconds (scipy.signal)
    from ..sysid.dataset import IdData

__all__ = ['BagDataset', 'load_bag_dataset', 'read_bag']


def _channels(specs: Sequence[str | Channel] | str | None) -> tuple[Channel, ...]:
    if specs is None:
        return ()
    if isinstance(specs, (str, Channel)):
        specs = [specs]
    return tuple(s if isinstance(s, Channel) else parse_channel(s) for s in specs)


@dataclass(frozen=True)
class BagDataset:
    """A data set read from a bag, with how it was made.

    Parameters
    ----------
    data : IdData
        Outputs ``y`` (N, ny), inputs ``u`` (N, nu), ``Ts`` in s, names and units.
    bag : str
        The bag's path.
    storage : str
        ``'mcap'`` or ``'sqlite3'``.
    outputs, inputs : tuple of Channel
        The channels, in data-set order.
    alignment : Alignment
        Time base, per-topic reports, gaps and trimmed samples.
    metadata : dict
        The run metadata stored in the bag.
    """

    data: IdData
    bag: str
    storage: str
    outputs: tuple[Channel, ...]
    inputs: tuple[Channel, ...]
    alignment: Alignment
    metadata: dict = field(default_factory=dict)

    @property
    def t0_ns(self) -> int:
        """Stamp of the first sample, ns."""
        return self.alignment.t0_ns

    @property
    def gaps(self) -> tuple[Gap, ...]:
        """Gaps found (and filled, as the data exists)."""
        return self.alignment.gaps

    def split(self, at: float | int = 0.5) -> tuple[IdData, IdData]:
        """Split into estimation and validation data (see :meth:`IdData.split`).

        Parameters
        ----------
        at : float or int
            Fraction in (0, 1) or sample index of the first validation sample.

        Returns
        -------
        tuple of IdData
            ``(estimation, validation)``.
        """
        return self.data.split(at)

    def summary(self, split: float | int | None = 0.5) -> dict:
        """Return a JSON-ready summary: duration, Ts, channels, samples, gaps, metadata.

        Parameters
        ----------
        split : float or int, optional
            Estimation/validation split to report (None: no split).

        Returns
        -------
        dict
            The summary.
        """
        data, al = self.data, self.alignment
        channels = []
        for role, chans, units in (
            ('output', self.outputs, data.output_units),
            ('input', self.inputs, data.input_units),
        ):
            for chan, unit in zip(chans, units, strict=True):
                channels.append(
                    {'name': chan.name, 'role': role, 'unit': unit, 'spec': chan.expression}
                )
        out = {
            'bag': self.bag,
            'storage': self.storage,
            'start_ns': al.t0_ns,
            'duration_s': data.N * data.Ts,
            'Ts_s': data.Ts,
            'samples': data.N,
            'channels': channels,
            'topics': [
                {
                    'topic': r.topic,
                    'role': r.role,
                    'clock': r.clock,
                    'messages': r.samples,
                    'period_s': r.period if np.isfinite(r.period) else None,
                    'method': r.method,
                    'duplicates': r.duplicates,
                }
                for r in al.reports
            ],
            'trimmed': {'start': al.trimmed[0], 'end': al.trimmed[1]},
            'gaps': [
                {'topic': g.topic, 'time_s': g.time, 'missing': g.missing, 'filled': g.filled}
                for g in al.gaps
            ],
            'metadata': dict(self.metadata),
        }
        if split is not None:
            est, val = self.split(split)
            out['estimation'] = {'samples': est.N, 'duration_s': est.N * est.Ts}
            out['validation'] = {'samples': val.N, 'duration_s': val.N * val.Ts}
        return out


def read_bag(
    path: str | Path,
    outputs: Sequence[str | Channel] | str,
    inputs: Sequence[str | Channel] | str | None = (),
    Ts: float | None = None,
    allow_gaps: bool = False,
    tolerance: float = TOLERANCE,
    fast: bool = True,
) -> BagDataset:
    """Read channels of a bag into a data set on one uniform time base.

    Parameters
    ----------
    path : str or Path
        rosbag2 bag directory (MCAP or sqlite3), or a single ``.mcap`` / ``.db3``.
    outputs : sequence of str or Channel
        Output channel specs, e.g. ``'maglev/sensor_0/field:magnetic_field.x'``;
        the first one's topic defines the time base.
    inputs : sequence of str or Channel, optional
        Input channel specs, e.g. ``'maglev/currents:effort[0]'``.
    Ts : float, optional
        Sample time in s (default: estimated from the first output's stamps).
    allow_gaps : bool
        Fill gaps (outputs linearly, inputs by zero-order hold) instead of refusing.
    tolerance : float
        Exact-match tolerance, fraction of ``Ts``.
    fast : bool
        Decode equal-layout messages by strided numpy reads (default); False
        deserialises every message (same result, slower).

    Returns
    -------
    BagDataset
        The data set and its report.

    Raises
    ------
    BagError
        Bad bag, unknown topic or field, bad spec, gaps (unless allowed).
    """
    outs, ins = _channels(outputs), _channels(inputs)
    if not outs:
        raise BagError('choose at least one output channel (TOPIC:FIELD)')
    # a topic is an output if any output channel reads it; outputs first, in order
    roles: dict[str, str] = {}
    for chan in outs:
        for topic in chan.topics:
            roles.setdefault(topic, 'output')
    for chan in ins:
        for topic in chan.topics:
            roles.setdefault(topic, 'input')
    refs: dict[str, list[FieldRef]] = {t: [] for t in roles}
    for chan in outs + ins:
        for _, ref in chan.terms:
            if ref not in refs[ref.topic]:
                refs[ref.topic].append(ref)
    with BagReader(path) as reader:
        samples = read_topics(reader, refs, fast=fast)
        metadata = reader.metadata
        storage = reader.storage
    sources = [Source(t, s.stamps, s.values, roles[t], s.clock) for t, s in samples.items()]
    alignment = align(sources, Ts=Ts, allow_gaps=allow_gaps, tolerance=tolerance)
    columns = {}
    for topic, block in zip(samples, alignment.values, strict=True):
        for k, ref in enumerate(refs[topic]):
            columns[ref] = block[:, k]

    def combine(chans: tuple[Channel, ...]) -> np.ndarray:
        out = np.zeros((alignment.N, len(chans)))
        for j, chan in enumerate(chans):
            if len(chan.terms) == 1 and chan.terms[0][0] == 1.0:
                out[:, j] = columns[chan.terms[0][1]]
                continue
            for coef, ref in chan.terms:
                out[:, j] += coef * columns[ref]
        return out

    from ..sysid.dataset import IdData

    try:
        data = IdData(
            combine(outs),
            combine(ins),
            alignment.Ts,
            [c.name for c in outs],
            [c.name for c in ins],
            [unit_of(c) for c in outs],
            [unit_of(c) for c in ins],
        )
    except ValueError as exc:
        raise BagError(f'bag {str(path)!r}: {exc}') from None
    return BagDataset(data, str(path), storage, outs, ins, alignment, metadata)


def load_bag_dataset(
    path: str | Path,
    outputs: Sequence[str] | str,
    inputs: Sequence[str] | str | None = (),
    Ts: float | None = None,
    allow_gaps: bool = False,
    tolerance: float = TOLERANCE,
) -> IdData:
    """Read a bag into an :class:`IdData` (the ``maglev-sysid`` entry point).

    Parameters
    ----------
    path : str or Path
        rosbag2 bag directory (MCAP or sqlite3).
    outputs, inputs : sequence of str
        Channel specs (see :func:`read_bag`).
    Ts : float, optional
        Sample time in s (default: from the stamps).
    allow_gaps : bool
        Fill gaps instead of refusing.
    tolerance : float
        Exact-match tolerance, fraction of ``Ts``.

    Returns
    -------
    IdData
        Outputs, inputs, ``Ts``, names and units.
    """
    return read_bag(path, outputs, inputs, Ts=Ts, allow_gaps=allow_gaps, tolerance=tolerance).data
