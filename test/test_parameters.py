"""The parameter spec (maglev_ros.parameters), without ROS."""

from __future__ import annotations

import importlib

import pytest

from maglev_ros.nodes.params import ParameterTable
from maglev_ros.parameters import (
    KINDS,
    NodeParameterError,
    Param,
    choice,
    coerce,
    help_requested,
    integer,
    number,
)


class DemoError(NodeParameterError):
    """A demo node's parameter error."""


TABLE = ParameterTable(
    'demo',
    DemoError,
    {
        'rate': Param(5000.0, 'samples per second, Hz', check=number(0, above=True)),
        'count': Param(1, 'how many', check=integer(1, 64)),
        'mode': Param('a', 'mode', check=choice('a', 'b')),
        'state': Param([], 'numbers; empty: none', kind='double_array'),
        'on': Param(True, 'switch'),
        'limit': Param(1.0, 'A', check=number(0), mutable=True),
    },
)


def test_an_integer_is_accepted_for_a_double():
    values = TABLE.validate({'rate': 5000, 'state': [1, 2.5]})
    assert values['rate'] == 5000.0 and type(values['rate']) is float
    assert values['state'] == (1.0, 2.5)


@pytest.mark.parametrize(
    'name, value, message',
    [
        ('count', 1.5, 'count must be an integer, got 1.5'),
        ('rate', 'fast', "rate must be a number, got 'fast'"),
        ('rate', True, 'rate must be a number, got True'),
        ('on', 1, 'on must be true or false, got 1'),
        ('mode', 3, 'mode must be a string, got 3'),
        ('state', [1.0, 'x'], "state must be a list of numbers, got [1.0, 'x']"),
        ('state', 'abc', "state must be a list of numbers, got 'abc'"),
    ],
)
def test_other_type_errors_name_parameter_and_value(name, value, message):
    with pytest.raises(DemoError) as err:
        TABLE.validate({name: value})
    assert str(err.value) == message


@pytest.mark.parametrize(
    'name, value, message',
    [
        ('rate', 0, 'rate must be a finite number > 0, got 0.0'),
        ('rate', float('nan'), 'rate must be a finite number > 0, got nan'),
        ('count', 65, 'count must be in 1 .. 64, got 65'),
        ('mode', 'c', "mode must be one of a, b, got 'c'"),
        ('limit', -1.0, 'limit must be a finite number >= 0, got -1.0'),
    ],
)
def test_value_rules(name, value, message):
    with pytest.raises(DemoError, match=message):
        TABLE.validate({name: value})


def test_missing_and_unset_values_take_the_default():
    values = TABLE.validate({'state': None})
    assert values == {
        'rate': 5000.0,
        'count': 1,
        'mode': 'a',
        'state': (),
        'on': True,
        'limit': 1.0,
    }
    assert TABLE.mutable == ('limit',)


def test_help_lists_every_parameter_with_type_default_and_rule():
    text = TABLE.help_text('demo_exec')
    assert text.startswith('usage: ros2 run maglev_ros demo_exec [--ros-args -p NAME:=VALUE')
    lines = {line.split()[0]: line for line in text.splitlines()[3:]}
    assert set(lines) == set(TABLE)
    assert 'double, > 0, default 5000.0: samples per second, Hz' in lines['rate']
    assert 'integer, 1 .. 64, default 1' in lines['count']
    assert 'string, one of a, b' in lines['mode']
    assert 'double_array, default []' in lines['state']
    assert 'bool, default true' in lines['on']
    assert 'settable at run time' in lines['limit']


@pytest.mark.parametrize(
    'argv, asked',
    [
        (['simulator', '--help'], True),
        (['simulator', '-h'], True),
        (['simulator'], False),
        (['simulator', '--ros-args', '-p', 'x:=1'], False),
        (['simulator', '--ros-args', '--help'], False),  # ROS's own help
        (['--help'], True),
    ],
)
def test_help_requested(argv, asked):
    assert help_requested(argv) is asked


def test_table_needs_a_node_parameter_error():
    with pytest.raises(TypeError, match='must subclass NodeParameterError'):
        ParameterTable('x', ValueError, {})


@pytest.mark.parametrize(
    'module',
    [
        'simulator',
        'driver',
        'excitation',
        'recorder',
        'player',
        'identifier',
        'estimator',
        'controller',
    ],
    ids=str,
)
def test_every_node_has_one_table_and_one_error_base(module):
    mod = importlib.import_module(f'maglev_ros.nodes.{module}')
    table = mod.PARAMETERS
    assert isinstance(table, ParameterTable)
    assert getattr(mod, '_PARAMETERS', table) is table  # the older name, where kept
    assert issubclass(table.error, NodeParameterError)
    for name, param in table.items():
        assert param.description, name
        assert param.type_kind in KINDS
        coerce(name, param.type_kind, param.default)  # every default has its kind


_REMOVED = ParameterTable(
    'demo',
    DemoError,
    {'rate': Param(1.0, 'a rate, Hz')},
    removed={'intra_process': 'the loop node composes the hot path (ros2 run maglev_ros loop)'},
)


def test_a_removed_parameter_is_refused_with_its_replacement():
    assert _REMOVED.validate({'rate': 2.0}) == {'rate': 2.0}
    with pytest.raises(DemoError, match=r'^intra_process was removed: the loop node composes'):
        _REMOVED.validate({'rate': 2.0, 'intra_process': True})


@pytest.mark.parametrize('given', [False, True])
def test_a_removed_parameter_given_to_a_node_is_refused_and_absent_otherwise(ctx, given):
    from rclpy.node import Node
    from rclpy.parameter import Parameter

    overrides = [Parameter('intra_process', value=True)] if given else []
    node = Node('demo', context=ctx, parameter_overrides=overrides)
    try:
        if given:
            with pytest.raises(DemoError, match='intra_process was removed: the loop node'):
                _REMOVED.declare(node)
        else:
            assert _REMOVED.declare(node) == {'rate': 1.0}
            assert not node.has_parameter('intra_process')
    finally:
        node.destroy_node()
