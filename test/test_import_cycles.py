"""No import cycles among maglev_ros's modules; layers import downwards only.

Every ``import`` and ``from ... import`` of a maglev_ros module counts, at
module level or inside a function (a function-level import that closes a
cycle is a cycle postponed, not removed). ``from pkg import name`` points at
``pkg.name`` when that is a module, else at the package.
"""

from __future__ import annotations

import ast
from pathlib import Path

import maglev_ros

ROOT = Path(maglev_ros.__file__).resolve().parent


def _module_name(path: Path) -> str:
    parts = ('maglev_ros', *path.relative_to(ROOT).with_suffix('').parts)
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def import_graph() -> dict[str, set[str]]:
    """``module -> modules of maglev_ros it imports``."""
    paths = {_module_name(p): p for p in ROOT.rglob('*.py')}
    graph: dict[str, set[str]] = {name: set() for name in paths}
    for name, path in paths.items():
        package = name if path.name == '__init__.py' else name.rpartition('.')[0]
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ''
                if node.level:
                    anchor = package.split('.')
                    anchor = anchor[: len(anchor) - (node.level - 1)]
                    base = '.'.join(anchor + ([base] if base else []))
                for alias in node.names:
                    full = f'{base}.{alias.name}'
                    targets.append(full if full in paths else base)
            for target in targets:
                while target and target not in paths:  # a name inside a module
                    target = target.rpartition('.')[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_import_cycles():
    assert cycles(import_graph()) == []


def test_the_check_sees_a_cycle():
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}}
    assert cycles(graph) == [['a', 'b', 'c']]


def test_the_graph_sees_function_level_and_relative_imports():
    graph = import_graph()
    assert 'maglev_ros.physics.equilibria' in graph['maglev_ros.physics.simulation']  # lazy
    assert 'maglev_ros.physics.kernels' in graph['maglev_ros.physics.model']  # from . import


def test_ros_free_layers_do_not_import_the_nodes():
    graph = import_graph()
    for name, targets in graph.items():
        layer = name.split('.')[1] if '.' in name else ''
        if layer in ('physics', 'sysid', 'hardware', 'bags', 'excitation', 'topics'):
            assert not {t for t in targets if t.startswith('maglev_ros.nodes')}, name
            assert not {t for t in targets if t.startswith('maglev_ros.cli')}, name
