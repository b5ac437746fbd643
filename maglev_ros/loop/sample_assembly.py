"""Assemble a sample's messages by stamp, whatever order they are handled in.

A sample of the lockstep graph or the board is several messages with one
stamp (the field of each sensor, ``maglev/currents``; for the controller the
estimate too). Each topic is delivered in order (one publisher, RELIABLE),
but messages of *different* topics reach a node's callbacks in any order:
the currents of sample k may be handled before a field of sample k. So a
sample is collected part by part and released, in stamp order, once

1. every part of it arrived (it is *complete*); or
2. every part it lacks is known lost: a message of a later stamp arrived on
   that part's topic (in-order delivery: the one of this stamp never will); or
3. a later sample is complete; or
4. messages of stamps more than ``wait_ns`` later arrived (a part whose topic
   went silent: a dead sensor or a cut estimator).

A part counts as missing only then, never because of callback order, so the
same messages give the same released samples in any handling order. Parts
of a sample already released (late) are dropped and counted. ROS-free.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ['ReleasedSample', 'SampleAssembler']


@dataclass(frozen=True)
class ReleasedSample:
    """A sample released by :class:`SampleAssembler`.

    Attributes
    ----------
    stamp : int
        ns.
    parts : tuple
        The value of each part, None for a missing one.
    """

    stamp: int
    parts: tuple

    @property
    def complete(self) -> bool:
        """Whether every part arrived."""
        return all(p is not None for p in self.parts)


class SampleAssembler:
    """Collect the parts of each stamp; release samples in stamp order (module docstring).

    Parameters
    ----------
    n_parts : int
        Parts per sample (messages of one stamp on distinct topics).
    wait_ns : int
        ns of stamps a sample waits for a part whose topic went silent.

    Attributes
    ----------
    late : int
        Parts dropped because their sample was released already.
    released : int
        Stamp of the last sample released, ns (-1 before any).
    """

    def __init__(self, n_parts: int, wait_ns: int) -> None:
        if n_parts < 1:
            raise ValueError(f'n_parts must be >= 1, got {n_parts!r}')
        if wait_ns < 0:
            raise ValueError(f'wait_ns must be >= 0, got {wait_ns!r}')
        self.n_parts = int(n_parts)
        self.wait_ns = int(wait_ns)
        self._pending: dict[int, list] = {}
        self._newest_part = [-1] * self.n_parts  # newest stamp seen per part
        self._newest = -1
        self.released = -1
        self.late = 0

    @property
    def pending(self) -> int:
        """Samples collected but not released."""
        return len(self._pending)

    def add(self, part: int, stamp: int, value) -> list[ReleasedSample]:
        """Add one part of the sample at ``stamp``; return the samples it releases, in order.

        Parameters
        ----------
        part : int
            0 .. n_parts - 1.
        stamp : int
            The message's stamp, ns.
        value : object
            The part (not None).

        Returns
        -------
        list of ReleasedSample
            Oldest first (usually none or one).
        """
        if stamp <= self.released:
            self.late += 1
            return []
        row = self._pending.get(stamp)
        if row is None:
            row = self._pending[stamp] = [None] * self.n_parts
        row[part] = value
        if stamp > self._newest_part[part]:
            self._newest_part[part] = stamp
        if stamp > self._newest:
            self._newest = stamp
        if len(self._pending) == 1:
            # the usual case, one sample in flight: it goes once complete; incomplete,
            # no part of a later stamp can have come (that sample would be pending)
            for v in row:  # (not `None in row`: == on numpy parts)
                if v is None:
                    return []
            del self._pending[stamp]
            self.released = stamp
            return [ReleasedSample(stamp, tuple(row))]
        return self._release()

    def handled(self, stamp: int) -> None:
        """Record complete samples up to ``stamp`` handled without :meth:`add` (a burst path).

        Their parts count as seen and their stamps as released: a later part
        of one of them is late, as if it had come through :meth:`add`.

        Parameters
        ----------
        stamp : int
            The newest such sample's stamp, ns (newer than :attr:`released`).

        Raises
        ------
        ValueError
            If samples are pending (release them first) or ``stamp`` is not newer
            than the last released one.
        """
        if self._pending:
            raise ValueError(f'{len(self._pending)} samples pending: add() their parts first')
        if stamp <= self.released:
            raise ValueError(f'stamp {stamp} is not newer than the released {self.released}')
        self.released = stamp
        self._newest = max(self._newest, stamp)
        self._newest_part = [max(v, stamp) for v in self._newest_part]

    def _release(self) -> list[ReleasedSample]:
        pending = self._pending
        newest_complete = max(
            (s for s, row in pending.items() if all(v is not None for v in row)), default=-1
        )
        out: list[ReleasedSample] = []
        for stamp in sorted(pending):
            row = pending[stamp]
            if not (
                stamp <= newest_complete
                or self._newest - stamp > self.wait_ns
                or all(v is not None or self._newest_part[p] > stamp for p, v in enumerate(row))
            ):
                break
            del pending[stamp]
            self.released = stamp
            out.append(ReleasedSample(stamp, tuple(row)))
        return out
