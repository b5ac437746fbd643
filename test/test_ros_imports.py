"""rclpy and the message packages are imported only in ``maglev_ros/nodes`` and ``maglev_ros/cli``.

Every other module is the ROS-free core (physics, sysid, greybox, hardware,
bags, estimation, control, excitation, loop, ...): it installs and runs with
pip alone. The check reads each module's syntax tree, so an import inside a
function counts as much as one at the top.
"""

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'maglev_ros'
ROS_SHELLS = ('nodes', 'cli')  # where rclpy may be imported
ROS_PACKAGES = {'rclpy', 'rosidl_runtime_py', 'builtin_interfaces', 'launch', 'launch_ros'}


def _is_ros(module: str) -> bool:
    top = module.split('.')[0]
    return top in ROS_PACKAGES or top.endswith(('_msgs', '_srvs', '_interfaces'))


def _ros_imports(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            found += [f'{a.name} (line {node.lineno})' for a in node.names if _is_ros(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and _is_ros(node.module or ''):
            found.append(f'{node.module} (line {node.lineno})')
    return found


CORE_MODULES = sorted(
    p for p in PACKAGE.rglob('*.py') if p.relative_to(PACKAGE).parts[0] not in ROS_SHELLS
)


@pytest.mark.parametrize('path', CORE_MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_core_module_imports_no_ros(path):
    assert _ros_imports(path) == []


def test_the_check_finds_an_import_inside_a_function(tmp_path):
    module = tmp_path / 'm.py'
    module.write_text('def f():\n    from sensor_msgs.msg import JointState\n    import rclpy\n')
    assert _ros_imports(module) == ['sensor_msgs.msg (line 2)', 'rclpy (line 3)']
    assert len(CORE_MODULES) > 50  # the package's core was found
