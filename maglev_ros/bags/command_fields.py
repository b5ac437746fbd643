"""Coil commands in either message type: ``data[i]`` and ``effort[i]`` name the same current.

``maglev/currents/command`` and ``maglev/currents/excitation`` are
``sensor_msgs/JointState`` (names ``x+ x- y+ y-``, ``effort`` in A,
``header.stamp`` = the sample the command answers). Bags recorded before carry
them as ``std_msgs/Float64MultiArray`` (``data`` in A, no header), and channel
specs, configuration files and launch files written for those say
``maglev/currents/command:data[0]``.

The rule, on these two topics only: a path ``data[i]`` read from a JointState
message reads ``effort[i]``, and ``effort[i]`` read from a Float64MultiArray
reads ``data[i]``. Any spec, old or new, then reads any bag, old or new, and
the live messages of either publisher; every other path and topic is left as
written.
"""

from __future__ import annotations

from collections.abc import Callable

from .channels import COMMAND_TOPICS, Channel, FieldRef, command_alias

__all__ = ['COMMAND_ARRAYS', 'COMMAND_TOPICS', 'command_alias', 'resolve_channel', 'resolve_ref']

#: The array field holding the currents, per message type of a command.
COMMAND_ARRAYS = {
    'sensor_msgs/msg/JointState': 'effort',
    'std_msgs/msg/Float64MultiArray': 'data',
}


def resolve_ref(ref: FieldRef, msgtype: str) -> FieldRef:
    """Return the reference that reads ``ref``'s current from messages of ``msgtype``.

    Parameters
    ----------
    ref : FieldRef
        A field reference.
    msgtype : str
        The type of the topic's messages, ``pkg/msg/Type``.

    Returns
    -------
    FieldRef
        ``ref`` itself, or its alias if ``ref`` names the array the other
        command type has (see the module docstring).
    """
    alias = command_alias(ref)
    if alias is not None and COMMAND_ARRAYS.get(msgtype) == alias.path[0]:
        return alias
    return ref


def resolve_channel(channel: Channel, msgtype_of: Callable[[str], str]) -> Channel:
    """Return ``channel`` with each term resolved for its topic's message type.

    Parameters
    ----------
    channel : Channel
        A parsed channel.
    msgtype_of : callable
        ``msgtype_of(topic) -> 'pkg/msg/Type'`` (absolute topic names).

    Returns
    -------
    Channel
        Same name and spec; terms as :func:`resolve_ref` gives them.
    """
    terms = tuple((coef, resolve_ref(ref, msgtype_of(ref.topic))) for coef, ref in channel.terms)
    return Channel(channel.name, terms, channel.spec)
