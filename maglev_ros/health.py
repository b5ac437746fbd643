"""A component's health as ``/diagnostics`` reports it, ROS-free.

The cores compute what a node publishes on ``/diagnostics`` (level, message,
key/value pairs); the node only wraps it in a ``diagnostic_msgs`` message.
The levels are those of ``diagnostic_msgs/DiagnosticStatus``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

__all__ = ['ERROR', 'OK', 'WARN', 'Health']

OK = 0  # DiagnosticStatus.OK
WARN = 1  # DiagnosticStatus.WARN
ERROR = 2  # DiagnosticStatus.ERROR


@dataclass(frozen=True)
class Health:
    """One diagnostics status.

    Attributes
    ----------
    level : int
        ``OK``, ``WARN`` or ``ERROR``.
    message : str
        One line for people.
    values : mapping of str to object
        Key/value pairs, in order (values are shown with ``str``).
    """

    level: int
    message: str
    values: Mapping[str, object]
