"""A node's parameter table on ROS: declaration and the on-set rules.

The table, its rules and ``--help`` are ROS-free (:mod:`maglev_ros.parameters`,
where the core configs declare their fields); this subclass adds what needs a
node: declaring every parameter with its descriptor, refusing removed ones, and
the run-time on-set callback.
"""

from __future__ import annotations

from collections.abc import Callable

from maglev_ros import parameters as _core
from maglev_ros.parameters import (
    PARAMS,
    NodeParameterError,
    Param,
    choice,
    config_params,
    help_requested,
    integer,
    node_name,
    number,
    topic_names,
)

__all__ = [
    'PARAMS',
    'NodeParameterError',
    'Param',
    'ParameterTable',
    'choice',
    'config_params',
    'help_requested',
    'integer',
    'node_name',
    'number',
    'topic_names',
]


class ParameterTable(_core.ParameterTable):
    """A node's parameters (:class:`maglev_ros.parameters.ParameterTable`) on ROS."""

    def declare(self, node) -> dict[str, object]:
        """Declare every parameter on ``node`` and return the raw values.

        Parameters
        ----------
        node : rclpy.node.Node
            The node (overrides from ``--ros-args`` or a launch file apply).

        Returns
        -------
        dict
            ``name -> value`` as rclpy holds it (to :meth:`validate`, or the
            node's ``build_config``).

        Raises
        ------
        NodeParameterError
            If a removed parameter was given a value.
        """
        from rcl_interfaces.msg import ParameterDescriptor

        for name in self.removed:
            # declared untyped to see whether an override names it, then undeclared
            given = node.declare_parameter(
                name, None, ParameterDescriptor(dynamic_typing=True)
            ).value
            node.undeclare_parameter(name)
            if given is not None:
                self.refuse_removed(name)
        values = {}
        for name, param in self._params.items():
            # Ranges go into the text, not the descriptor's range fields: rclpy
            # applies those to overrides inside declare_parameter, with its own
            # exception, before the node's rule could name the value.
            descriptor = ParameterDescriptor(
                description=param.description,
                read_only=not param.mutable,
                dynamic_typing=True,  # the table's type rule applies (ints for doubles)
                additional_constraints=param.constraints,
            )
            default = list(param.default) if isinstance(param.default, tuple) else param.default
            values[name] = node.declare_parameter(name, default, descriptor).value
        return values

    def on_set(self, node, rebuild: Callable[[dict[str, object]], object]):
        """Return an on-set-parameters callback enforcing the table's rules at run time.

        The callback applies each parameter's rules, then ``rebuild`` to every
        current value with the changes applied (the same ``build_config`` as
        at start-up); it stores the result as ``node.config`` or refuses the
        change with the error's message.

        Parameters
        ----------
        node : rclpy.node.Node
            The node (parameters declared).
        rebuild : callable
            ``rebuild(values) -> config``, raising :class:`NodeParameterError`.

        Returns
        -------
        callable
            For ``node.add_on_set_parameters_callback``.
        """
        from rcl_interfaces.msg import SetParametersResult

        def callback(params) -> SetParametersResult:
            changes = {p.name: p.value for p in params if p.name in self._params}
            if not changes:
                return SetParametersResult(successful=True)
            values = {name: node.get_parameter(name).value for name in self._params}
            try:
                for name, value in changes.items():
                    self.check_value(name, value)
                config = rebuild(values | changes)
            except NodeParameterError as err:
                return SetParametersResult(successful=False, reason=str(err))
            node.config = config
            return SetParametersResult(successful=True)

        return callback
