"""The launch files name only installed executables and declared parameters.

The XML is parsed with ``xml.etree`` (an executable is a console script of
this distribution, its node module's ``PARAMETERS`` are the parameters it
declares), and each file's conditions are evaluated by the launch package for
each plant (:func:`launched`), without starting anything.
"""

import importlib
import xml.etree.ElementTree as ET
from importlib.metadata import distribution
from pathlib import Path

import pytest

LAUNCH = Path(__file__).resolve().parents[1] / 'launch'
BUILT_IN = {'use_sim_time'}


def console_scripts():
    entry_points = distribution('maglev_ros').entry_points
    return {ep.name: ep.value for ep in entry_points if ep.group == 'console_scripts'}


@pytest.mark.parametrize('path', sorted(LAUNCH.glob('*.launch.xml')), ids=lambda p: p.name)
def test_nodes_executables_and_parameters_exist(path):
    root = ET.parse(path).getroot()
    assert root.tag == 'launch'
    scripts = console_scripts()
    nodes = root.findall('.//node')
    assert nodes
    for node in nodes:
        assert node.get('pkg') == 'maglev_ros'
        executable = node.get('exec')
        assert executable in scripts, f'{path.name}: no executable {executable!r}'
        module = importlib.import_module(scripts[executable].split(':')[0])
        declared = set(module.PARAMETERS) | BUILT_IN
        for param in node.findall('param'):
            assert param.get('name') in declared, (
                f'{path.name}: {executable} declares no parameter {param.get("name")!r}'
            )
    args = {a.get('name') for a in root.findall('arg')}
    for element in root.iter():
        for value in element.attrib.values():
            if '$(var ' in value:
                name = value.split('$(var ')[1].split(')')[0]
                assert name in args, f'{path.name}: undeclared launch argument {name!r}'


def launched(name: str, **args: str) -> dict[str, dict[str, str]]:
    """Evaluate a launch file's conditions with ``args``: ``{executable: {param: value}}``.

    Parsed and evaluated by the launch package (its XML front end and
    conditions), without starting anything.
    """
    import os
    import sys

    from launch.actions import DeclareLaunchArgument, GroupAction
    from launch.frontend import Parser
    from launch.utilities import perform_substitutions
    from launch_ros.actions import Node

    from launch import LaunchContext

    os.environ.setdefault('AMENT_PREFIX_PATH', sys.prefix)  # the launch grammar's share
    root, parser = Parser.load(str(LAUNCH / name))
    context = LaunchContext()
    context.launch_configurations.update(args)
    nodes: dict[str, dict[str, str]] = {}

    def walk(entities) -> None:
        for entity in entities:
            if isinstance(entity, DeclareLaunchArgument):
                if entity.choices is not None and entity.name in args:
                    assert args[entity.name] in entity.choices, entity.choices
                if entity.name not in context.launch_configurations:
                    value = perform_substitutions(context, entity.default_value)
                    context.launch_configurations[entity.name] = value
            elif entity.condition is not None and not entity.condition.evaluate(context):
                continue
            elif isinstance(entity, GroupAction):
                walk(entity.get_sub_entities())
            elif isinstance(entity, Node):
                executable = perform_substitutions(context, entity.node_executable)
                xml = [n for n in ET.parse(LAUNCH / name).getroot().iter('node')]
                params = {}
                for element in xml:
                    if element.get('exec') == executable:
                        for param in element.findall('param'):
                            params[param.get('name')] = param.get('value')
                nodes[executable] = params

    walk(parser.parse_description(root).entities)
    return nodes


def test_three_launch_files_each_for_the_simulator_or_a_board():
    assert sorted(p.name for p in LAUNCH.glob('*.launch.xml')) == [
        'closed_loop.launch.xml', 'closed_loop_lab.launch.xml', 'lab.launch.xml',
    ]  # fmt: skip
    for name in ('lab.launch.xml', 'closed_loop.launch.xml', 'closed_loop_lab.launch.xml'):
        root = ET.parse(LAUNCH / name).getroot()
        plant = [a for a in root.findall('arg') if a.get('name') == 'plant']
        assert plant and plant[0].get('default') == 'simulator', name
        assert [c.get('value') for c in plant[0].findall('choice')] == ['simulator', 'board']


@pytest.mark.parametrize(
    ('name', 'args', 'executables'),
    [
        ('lab.launch.xml', {}, ['simulator', 'excitation', 'recorder']),
        ('lab.launch.xml', {'plant': 'board'}, ['driver', 'excitation', 'recorder']),
        ('closed_loop.launch.xml', {}, ['loop']),
        ('closed_loop.launch.xml', {'record': 'true'}, ['loop', 'recorder']),
        ('closed_loop.launch.xml', {'plant': 'board'}, ['loop']),
        ('closed_loop.launch.xml', {'separate': 'true'}, ['simulator', 'estimator', 'controller']),
        (
            'closed_loop.launch.xml',
            {'separate': 'true', 'plant': 'board', 'record': 'true'},
            ['driver', 'estimator', 'controller', 'recorder'],
        ),
        (
            'closed_loop_lab.launch.xml',
            {},
            ['simulator', 'estimator', 'controller', 'identifier', 'recorder'],
        ),
        (
            'closed_loop_lab.launch.xml',
            {'plant': 'board'},
            ['driver', 'estimator', 'controller', 'identifier', 'recorder'],
        ),
    ],
)
def test_each_plant_starts_its_nodes(name, args, executables):
    assert list(launched(name, **args)) == executables


@pytest.mark.parametrize('plant', ['simulator', 'board'])
def test_closed_loop_lab_excites_identifies_and_records_the_excitation(plant):
    nodes = launched('closed_loop_lab.launch.xml', plant=plant)
    assert nodes['controller']['excitation_signal'] == '$(var signal)'
    assert 'maglev/currents/excitation' in nodes['recorder']['topics']


CONFIG = LAUNCH.parent / 'config'
NODE_MODULES = {
    'maglev_simulator': 'maglev_ros.nodes.simulator',
    'maglev_excitation': 'maglev_ros.nodes.excitation',
    'maglev_recorder': 'maglev_ros.nodes.recorder',
    'maglev_player': 'maglev_ros.nodes.player',
}


@pytest.mark.parametrize('path', sorted(CONFIG.glob('*_params.yaml')), ids=lambda p: p.name)
def test_parameter_files_name_declared_parameters_with_their_types(path):
    import yaml

    data = yaml.safe_load(path.read_text())
    for node, section in data.items():
        module = importlib.import_module(NODE_MODULES[node])
        for name, value in section['ros__parameters'].items():
            assert name in module._PARAMETERS, f'{path.name}: {node} has no parameter {name!r}'
            default = module._PARAMETERS[name][0]
            if not hasattr(default, 'name'):  # a typed default, not Parameter.Type
                assert type(value) is type(default), (
                    f'{path.name}: {name} = {value!r} is not a {type(default).__name__}'
                )
                assert value == default, f'{path.name}: {name} = {value!r}, default {default!r}'


def test_closed_loop_launch_composes_the_loop_unless_separate():
    root = ET.parse(LAUNCH / 'closed_loop.launch.xml').getroot()
    defaults = {a.get('name'): a.get('default') for a in root.findall('arg')}
    assert defaults['separate'] == 'false'
    assert launched('closed_loop.launch.xml', record='true')['loop']['plant'] == '$(var plant)'
