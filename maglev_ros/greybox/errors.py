"""The grey-box package's error type."""

from __future__ import annotations

__all__ = ['GreyBoxError']


class GreyBoxError(ValueError):
    """Invalid grey-box input (parameter name, bounds, data); the message names the value."""
