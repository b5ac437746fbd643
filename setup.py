"""Build script for maglev_ros (ament_python; also a plain pip package)."""

import os
import subprocess
import sys
from glob import glob

from setuptools import find_packages, setup
from setuptools.command.install import install

HERE = os.path.dirname(os.path.abspath(__file__))

PACKAGE = 'maglev_ros'

# Command-line tools: installed as ``maglev-<verb>`` (pip) and as ``<verb>``
# so that ``ros2 run maglev_ros <verb>`` finds them after ``colcon build``.
CLI_TOOLS = {
    'model': 'maglev_ros.cli.model:main',
    'sysid': 'maglev_ros.cli.sysid:main',
    'lab': 'maglev_ros.cli.lab:main',
    'bag2data': 'maglev_ros.cli.bag2data:main',
    'calibrate': 'maglev_ros.cli.calibrate:main',
    'study': 'maglev_ros.cli.study:main',
}
# The documentation site (mkdocs.yml): MkDocs, the Material theme, the API from the
# numpy docstrings. The test suite builds it strictly, so the test extra has them too.
DOCS = ['mkdocs>=1.6', 'mkdocs-material>=9.5', 'mkdocstrings[python]>=0.26']
# ROS nodes, named plainly for ``ros2 run maglev_ros <node>``.
NODES: dict[str, str] = {
    'virtual_board': 'maglev_ros.cli.virtual_board:main',
    'maglev-virtual-board': 'maglev_ros.cli.virtual_board:main',
    'driver': 'maglev_ros.nodes.driver:main',
    'simulator': 'maglev_ros.nodes.simulator:main',
    'excitation': 'maglev_ros.nodes.excitation:main',
    'recorder': 'maglev_ros.nodes.recorder:main',
    'player': 'maglev_ros.nodes.player:main',
    'identifier': 'maglev_ros.nodes.identifier:main',
    'estimator': 'maglev_ros.nodes.estimator:main',
    'controller': 'maglev_ros.nodes.controller:main',
    'loop': 'maglev_ros.nodes.loop:main',
}

console_scripts = [f'maglev-{verb}={target}' for verb, target in CLI_TOOLS.items()]
console_scripts += [f'{verb}={target}' for verb, target in CLI_TOOLS.items()]
console_scripts += [f'{name}={target}' for name, target in NODES.items()]


class InstallAndCompile(install):
    """``setup.py install`` (what ``colcon build`` runs), then the kernels compiled.

    A plain install into a prefix (not a wheel's staging root) fills the numba
    cache of the installed package (``python -m maglev_ros.cli.kernels``), so
    that a node started right after ``colcon build`` does not compile first.
    ``MAGLEV_BUILD_COMPILE=0`` skips it; a failure only warns.
    """

    def run(self) -> None:
        """Install, then compile the kernels into the installed package."""
        super().run()
        if self.root is not None or os.environ.get('MAGLEV_BUILD_COMPILE', '1') == '0':
            return
        env = dict(os.environ)
        env['PYTHONPATH'] = os.pathsep.join(
            filter(None, [self.install_lib, env.get('PYTHONPATH')])
        )
        cmd = [sys.executable, '-m', f'{PACKAGE}.cli.kernels', '--seed-from']
        cmd.append(os.path.join(HERE, PACKAGE))
        if subprocess.run(cmd, env=env, cwd=self.install_lib, check=False).returncode:
            print(f'warning: {PACKAGE}: kernels not compiled; the first run compiles them')


setup(
    name=PACKAGE,
    version='0.1.0',
    description='ROS 2 tools for the Maggy magnetic-levitation lab',
    license='Apache-2.0',
    python_requires='>=3.10',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
        (f'share/{PACKAGE}/launch', [f for f in glob('launch/*') if os.path.isfile(f)]),
    ],
    install_requires=[
        'setuptools',
        'numpy>=1.24',
        'scipy>=1.11',
        'numba>=0.59',
        'PyYAML>=6',
        'control>=0.10',
        'filterpy>=1.4.5',
        'pyserial>=3.5',
        'cobs>=1.2',
        'rosbags>=0.10',
        'matplotlib>=3.7',
        'tqdm>=4.60',
        # SINDy with control inputs (maglev_ros.sysid.sindy)
        'pysindy>=2.0',
        # maglev-study's engine: an embedded local cluster by default, or a lab's cluster
        'dask[distributed]>=2024.1',
    ],
    extras_require={
        # maglev-study writes Parquet with it (CSV without)
        'parquet': ['pyarrow>=14'],
        # The PyPI build of ROS 2 Jazzy's Python side, for machines without ROS.
        # A real ROS 2 install keeps its own rclpy: do not install this extra there.
        'ros': [
            'ros-jazzy-rclpy[fastrtps]',
            'ros-jazzy-common-interfaces',
        ],
        'docs': DOCS,
        'test': [
            *DOCS,
            'pytest>=7',
            'pytest-timeout>=2',
            'pyarrow>=14',
            'magpylib>=5',
            'colcon-common-extensions',
            # pinned: the formatter's output changes between minor versions
            'ruff==0.17.6',
            # NARX reference in test/sysid/test_narx.py and benchmarks/sysid.py
            'sysidentpy>=0.9',
        ],
    },
    entry_points={'console_scripts': console_scripts},
    cmdclass={'install': InstallAndCompile},
)
