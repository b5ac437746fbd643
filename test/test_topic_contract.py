"""No topic, frame or service name is typed outside the contract module.

Every name of ``docs/topics.md`` lives in :mod:`maglev_ros.topics`; the
nodes, the recorder, ``maglev-lab``, the bag converter and the physics take
it from there. This test walks the package's syntax trees and fails on any
string literal (docstrings aside) that spells a contract name.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import maglev_ros
from maglev_ros import topics

PACKAGE = Path(maglev_ros.__file__).resolve().parent
CONTRACT = PACKAGE / 'topics.py'
# a graph name under maglev/, an absolute /clock or /diagnostics, a contract frame
NAME = re.compile(
    r'(?<![\w.])/?maglev/\w|(?<![\w.])/(clock|diagnostics)\b|\bmaglev_(sensor_|base\b|magnet\b)'
)


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                ids.add(id(body[0].value))
    return ids


def contract_strings(path: Path) -> list[str]:
    """``line: text`` of each non-docstring string literal in ``path`` naming the contract."""
    tree = ast.parse(path.read_text(), filename=str(path))
    skip = _docstrings(tree)
    found = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and id(node) not in skip
            and NAME.search(node.value)
        ):
            found.append(f'{node.lineno}: {node.value!r}')
    return found


def test_no_topic_string_outside_the_contract_module():
    offenders = {
        str(path.relative_to(PACKAGE)): hits
        for path in sorted(PACKAGE.rglob('*.py'))
        if path != CONTRACT and (hits := contract_strings(path))
    }
    assert not offenders, f'contract names typed outside maglev_ros/topics.py: {offenders}'


def test_the_check_finds_a_typed_topic(tmp_path):
    sample = tmp_path / 'sample.py'
    sample.write_text('"""Doc naming maglev/currents."""\nTOPIC = "maglev/currents/command"\n')
    assert contract_strings(sample) == ["2: 'maglev/currents/command'"]


def test_contract_names_match_the_topic_document():
    assert topics.field_topic(2) == 'maglev/sensor_2/field'
    assert topics.sensor_frame(2) == 'maglev_sensor_2'
    assert topics.COIL_NAMES == ('x+', 'x-', 'y+', 'y-')
    for name in (
        topics.CURRENTS_TOPIC,
        topics.COMMAND_TOPIC,
        topics.TRUE_STATE_TOPIC,
        topics.ESTIMATE_TOPIC,
        topics.REFERENCE_TOPIC,
        topics.EXCITATION_TOPIC,
        topics.IDENTIFIER_MODEL_TOPIC,
        topics.MARKERS_TOPIC,
    ):
        assert name.startswith('maglev/') and name in topics.MESSAGE_TYPES
    assert topics.CLOCK_TOPIC == '/clock' and topics.DIAGNOSTICS_TOPIC == '/diagnostics'


def test_contract_module_needs_no_ros():
    tree = ast.parse(CONTRACT.read_text())
    imported = {
        alias.name.split('.')[0]
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    } | {node.module.split('.')[0] for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    assert imported <= {'__future__'}, imported
