"""The excitation's commands in order, each as a stamped command message, ROS-free.

:class:`CommandSequence` repeats one period of coil commands ``cycles`` times
(0: forever), then sends the offset alone; ``max_commands`` (0: no limit)
stops it after that many. Each command is serialised as the command contract's
``sensor_msgs/JointState`` (names x+ x- y+ y-, effort in A) stamped with the
sample it answers, by the compiled serialiser of :mod:`maglev_ros.cdr` (an
rclpy message object costs several times more to publish at 5 kHz).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..cdr import currents_layout
from ..cdr.batch import RawMessageBatch
from ..cdr.reader import RawFieldReader

__all__ = ['CommandSequence']


class CommandSequence:
    """One period of commands, repeated, then the offset; serialised on demand.

    Parameters
    ----------
    commands : ndarray, shape (length, 4)
        One period of coil currents, A, order x+ x- y+ y-.
    cycles : int
        Periods to send (0: forever).
    offset : sequence of float, shape (4,)
        Currents sent once the periods are done, A.
    max_commands : int, optional
        Commands to send in all (0: no limit).

    Attributes
    ----------
    sent : int
        Commands returned so far.
    """

    def __init__(
        self, commands: np.ndarray, cycles: int, offset: Sequence[float], max_commands: int = 0
    ) -> None:
        commands = np.asarray(commands, dtype=float)
        if commands.ndim != 2 or commands.shape[1] != 4 or not len(commands):
            raise ValueError(f'commands must have shape (length, 4), got {commands.shape}')
        self.commands = commands
        self.cycles = int(cycles)
        self.max_commands = int(max_commands)
        self.sent = 0
        self._rest = np.asarray(offset, dtype=float).reshape(1, 4)
        self._encoder = RawMessageBatch(currents_layout())
        self._stamps = RawFieldReader('sensor_msgs/msg/JointState', ())
        self._stamp = np.zeros(1, dtype=np.int64)

    @property
    def finished(self) -> bool:
        """True once all cycles were sent (the offset alone from then on)."""
        return bool(self.cycles) and self.sent >= self.cycles * len(self.commands)

    @property
    def exhausted(self) -> bool:
        """True once ``max_commands`` commands were sent (nothing more comes)."""
        return bool(self.max_commands) and self.sent >= self.max_commands

    def next(self) -> np.ndarray | None:
        """Return the next command, shape (4,), A (None once exhausted)."""
        if self.exhausted:
            return None
        finished = self.finished
        self.sent += 1
        return self._rest[0] if finished else self.commands[(self.sent - 1) % len(self.commands)]

    def message(self, stamp_ns: int) -> bytes | None:
        """Return the next command as a serialised JointState stamped ``stamp_ns`` (None: done).

        Parameters
        ----------
        stamp_ns : int
            Stamp of the sample the command answers (or the sender's time), ns.
        """
        command = self.next()
        if command is None:
            return None
        self._stamp[0] = stamp_ns
        return self._encoder.serialise(self._stamp, command[None, :])[0]

    def answer(self, sample: bytes) -> bytes | None:
        """Return the next command stamped with a sample's stamp (None: done or unreadable).

        Parameters
        ----------
        sample : bytes
            A serialised stamped message (``maglev/currents``, with its 4-byte
            encapsulation header) the command answers.
        """
        read = self._stamps.read(sample)
        return None if read is None else self.message(read[0])
