"""Parameters a node no longer has: refused with one line that says what replaced them.

rclpy ignores an override of a parameter a node does not declare, so a launch
file or a command line that still sets one would silently get other
behaviour. :func:`refuse_removed` declares each removed name for a moment,
refuses it if it was set, and undeclares it again (the node's parameter list
stays clean).
"""

from __future__ import annotations

from collections.abc import Mapping

__all__ = ['refuse_removed']


def refuse_removed(node, removed: Mapping[str, str], error: type[Exception]) -> None:
    """Raise ``error`` if any parameter of ``removed`` was set on ``node``.

    Parameters
    ----------
    node : rclpy.node.Node
        The node, before its own parameters are declared or after.
    removed : mapping
        ``name -> what replaced it`` (one clause, e.g. ``'the loop process
        composes the nodes'``).
    error : type
        The node's parameter error (exit status 2 in ``run_nodes``).

    Raises
    ------
    error
        ``NAME was removed: REPLACEMENT; delete it from the launch file or command line``.
    """
    from rcl_interfaces.msg import ParameterDescriptor

    for name, replacement in removed.items():
        descriptor = ParameterDescriptor(dynamic_typing=True)
        value = node.declare_parameter(name, None, descriptor).value
        node.undeclare_parameter(name)
        if value is not None:
            raise error(
                f'{name} was removed: {replacement}; delete it from the launch file, '
                'the parameter file or the command line'
            )
