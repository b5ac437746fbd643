"""The message definitions CDR code works with: ROS 2 Jazzy's standard types."""

from __future__ import annotations

from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

__all__ = ['jazzy_typestore']

_JAZZY: list[Typestore] = []


def jazzy_typestore() -> Typestore:
    """Return the shared rosbags type store of ROS 2 Jazzy's standard messages.

    Returns
    -------
    rosbags Typestore
        Built once per process.
    """
    if not _JAZZY:
        _JAZZY.append(get_typestore(Stores.ROS2_JAZZY))
    return _JAZZY[0]
