"""The launch files name only installed executables and declared parameters.

Checked without the launch package: the XML is parsed with ``xml.etree``; an
executable is a console script of this distribution, its node module's
``PARAMETERS`` are the parameters it declares.
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


@pytest.mark.parametrize('name', ['lab.launch.xml', 'lab_board.launch.xml'])
def test_lab_launch_exists(name):
    assert (LAUNCH / name).is_file()


@pytest.mark.parametrize(
    'name, source',
    [
        ('closed_loop.launch.xml', 'simulator'),
        ('closed_loop_board.launch.xml', 'driver'),
        ('closed_loop_lab.launch.xml', 'simulator'),
        ('closed_loop_lab_board.launch.xml', 'driver'),
    ],
)
def test_closed_loop_launch_files_run_source_estimator_and_controller(name, source):
    root = ET.parse(LAUNCH / name).getroot()
    executables = [node.get('exec') for node in root.findall('.//node')]
    assert {source, 'estimator', 'controller'} <= set(executables), executables
    assert executables.count('controller') == 1  # the only command publisher


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


@pytest.mark.parametrize(
    'name', ['closed_loop_lab.launch.xml', 'closed_loop_lab_board.launch.xml']
)
def test_closed_loop_lab_launch_files_excite_identify_and_record(name):
    root = ET.parse(LAUNCH / name).getroot()
    nodes = {node.get('exec'): node for node in root.findall('.//node')}
    assert {'estimator', 'controller', 'identifier', 'recorder'} <= set(nodes), sorted(nodes)
    params = {p.get('name'): p.get('value') for p in nodes['controller'].findall('param')}
    assert params['excitation_signal'] == '$(var signal)'
    recorded = {p.get('name'): p.get('value') for p in nodes['recorder'].findall('param')}
    assert 'maglev/currents/excitation' in recorded['topics']


def test_closed_loop_launch_composes_the_loop_unless_separate():
    root = ET.parse(LAUNCH / 'closed_loop.launch.xml').getroot()
    composed = [g for g in root.findall('group') if g.get('unless') == '$(var separate)']
    assert [n.get('exec') for n in composed[0].findall('node')] == ['loop', 'recorder']
    separate = [g for g in root.findall('group') if g.get('if') == '$(var separate)']
    assert [n.get('exec') for n in separate[0].findall('node')] == [
        'simulator', 'estimator', 'controller', 'recorder',
    ]  # fmt: skip
    defaults = {a.get('name'): a.get('default') for a in root.findall('arg')}
    assert defaults['separate'] == 'false'
