"""Topic and message-type names as bags store them."""

from __future__ import annotations

from .errors import BagError

__all__ = ['normalize_msgtype', 'normalize_topic']


def normalize_topic(name: str) -> str:
    """Return a topic name in the absolute form bags store (``/maglev/currents``).

    Parameters
    ----------
    name : str
        Topic name with or without the leading ``/``.

    Returns
    -------
    str
        The name with exactly one leading ``/`` and no trailing ``/``.
    """
    text = str(name).strip().strip('/')
    if not text or any(c.isspace() for c in text):
        raise BagError(f'invalid topic name {name!r}')
    return '/' + text


def normalize_msgtype(msgtype: str) -> str:
    """Return a message type as ``pkg/msg/Type`` (``sensor_msgs/MagneticField`` is accepted).

    Parameters
    ----------
    msgtype : str
        ``pkg/msg/Type`` or ``pkg/Type``.

    Returns
    -------
    str
        ``pkg/msg/Type``.
    """
    parts = str(msgtype).strip().split('/')
    if len(parts) == 2 and all(parts):
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and all(parts):
        return '/'.join(parts)
    raise BagError(f'invalid message type {msgtype!r}: expected pkg/msg/Type')
