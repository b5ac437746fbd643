"""Fetch every parameter of another node through its parameter services, without blocking.

The recorder stores the simulator's parameters in its bag's metadata. The
other node may appear late, answer its list late (under ``ros2 launch`` at
start-up), or answer nothing for a parameter that is declared but unset; so
the names are listed once, then asked for one at a time, a parameter that gets
no answer within ``timeout`` s skipped, and every answer kept as it comes (a
bag closed before the last answer stores those so far).
"""

from __future__ import annotations

import time
from collections.abc import Callable

from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import GetParameters, ListParameters

__all__ = ['RemoteParameters', 'parameter_value']

_SCALARS = {
    ParameterType.PARAMETER_BOOL: 'bool_value',
    ParameterType.PARAMETER_INTEGER: 'integer_value',
    ParameterType.PARAMETER_DOUBLE: 'double_value',
    ParameterType.PARAMETER_STRING: 'string_value',
}
_ARRAYS = {
    ParameterType.PARAMETER_BOOL_ARRAY: 'bool_array_value',
    ParameterType.PARAMETER_INTEGER_ARRAY: 'integer_array_value',
    ParameterType.PARAMETER_DOUBLE_ARRAY: 'double_array_value',
    ParameterType.PARAMETER_STRING_ARRAY: 'string_array_value',
}


def parameter_value(value) -> object:
    """Return a ``rcl_interfaces/ParameterValue`` as a Python value (arrays joined by spaces).

    Parameters
    ----------
    value : rcl_interfaces.msg.ParameterValue
        The value.

    Returns
    -------
    bool, int, float or str
        ``''`` for an unset parameter.
    """
    if value.type in _SCALARS:
        return getattr(value, _SCALARS[value.type])
    if value.type in _ARRAYS:
        return ' '.join(str(v) for v in getattr(value, _ARRAYS[value.type]))
    return ''


class RemoteParameters:
    """Every parameter of node ``name``, fetched one at a time (see the module docstring).

    Call :meth:`poll` now and then (a timer): it starts the fetch once the
    node's services are there and skips a parameter left unanswered.

    Parameters
    ----------
    node : rclpy.node.Node
        The asking node.
    name : str
        The other node's name.
    on_done : callable
        ``on_done(items)`` once every parameter was answered or skipped, with
        ``{'<name>.<parameter>': value}``.
    timeout : float
        Seconds to wait for one parameter's answer.
    """

    def __init__(self, node, name: str, on_done: Callable[[dict], None], timeout=0.3) -> None:
        self._node, self.name, self._on_done, self._timeout = node, name, on_done, timeout
        self.items: dict[str, object] = {}  # answered so far
        self.done = False
        self._pending = False
        self._skip: Callable[[], None] | None = None  # set while one parameter is asked for
        self._since = 0.0
        self._getter = None

    def poll(self) -> None:
        """Start the fetch if the node is up, or skip a parameter that got no answer."""
        if self.done:
            return
        if not self._pending:
            self._start()
        elif self._skip is not None and time.monotonic() - self._since > self._timeout:
            self._skip()

    def _start(self) -> None:
        node = self._node
        if self.name not in {n for n, _ in node.get_node_names_and_namespaces()}:
            return
        lister = node.create_client(ListParameters, f'/{self.name}/list_parameters')
        getter = node.create_client(GetParameters, f'/{self.name}/get_parameters')
        if not (lister.service_is_ready() and getter.service_is_ready()):
            node.destroy_client(lister)
            node.destroy_client(getter)
            return
        self._pending, self._getter = True, getter
        lister.call_async(ListParameters.Request()).add_done_callback(self._got_names)

    def _got_names(self, future) -> None:
        result = future.result()
        if result is None or not result.result.names:
            self._pending = False  # asked again at the next poll
            return
        self._ask(list(result.result.names))

    def _ask(self, names: list[str]) -> None:
        """Ask for ``names[0]`` (one parameter per request: an unset one gets no answer)."""
        if not names:
            self.done, self._skip = True, None
            self._on_done(dict(self.items))
            return
        self._since = token = time.monotonic()
        self._skip = lambda: self._ask(names[1:])

        def got_value(future) -> None:
            if token != self._since:
                return  # skipped after the timeout
            result = future.result()
            if result is not None and result.values:
                self.items[f'{self.name}.{names[0]}'] = parameter_value(result.values[0])
            self._ask(names[1:])

        request = GetParameters.Request(names=[names[0]])
        self._getter.call_async(request).add_done_callback(got_value)
