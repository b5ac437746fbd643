"""The one error type of :mod:`maglev_ros.bags`."""

from __future__ import annotations

__all__ = ['BagError']


class BagError(ValueError):
    """A bag, channel spec or alignment problem, with one message naming what is wrong.

    Raised for a missing or empty bag directory, a missing ``metadata.yaml``, a
    truncated or corrupt storage file, an unknown topic (the message lists the
    topics the bag has), an unknown field path (it lists the message's fields),
    a bad channel spec, and gaps in the data that were not allowed.
    """
