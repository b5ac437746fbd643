"""Public functions document their parameters (in the way of python-control's docstrings_test).

Every public function and method of the package (a name without a leading
underscore, in a module without one) with parameters has a numpy-style
docstring whose ``Parameters`` section names each of them (``*args`` and
``**kwargs`` as ``*args``/``**kwargs``); a class documents its ``__init__``'s
parameters in the class docstring. Read from the syntax trees, so nothing is
imported.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

import maglev_ros

ROOT = Path(maglev_ros.__file__).resolve().parent
_SECTION = re.compile(r'^\s*(Parameters|Other Parameters)\s*\n\s*-{3,}\s*$', re.M)
_ANY_SECTION = re.compile(r'^\s*[A-Z][A-Za-z ]+\s*\n\s*-{3,}\s*$', re.M)


def documented(docstring: str) -> set[str]:
    """Names in the ``Parameters`` sections of a numpy-style docstring."""
    names: set[str] = set()
    for match in _SECTION.finditer(docstring):
        body = docstring[match.end() :]
        following = _ANY_SECTION.search(body)
        body = body[: following.start()] if following else body
        for line in body.splitlines():
            if _is_entry(line):
                head = line.split(' : ')[0] if ' : ' in line else line.strip()
                names.update(part.strip().lstrip('*') for part in head.split(','))
    return names


def _is_entry(line: str) -> bool:
    """Whether a line of a Parameters section names parameters (``a, b : type``)."""
    indent = len(line) - len(line.lstrip())
    entry = r'^\s*\**[A-Za-z_]\w*(\s*,\s*\**[A-Za-z_]\w*)*\s*(:|$)'
    return indent == 0 and re.match(entry, line) is not None  # docstrings come dedented


def _parameters(node: ast.FunctionDef, method: bool) -> list[str]:
    args = node.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    if method and names and names[0] in ('self', 'cls'):
        names = names[1:]
    if args.vararg:
        names.append(args.vararg.arg)
    if args.kwarg:
        names.append(args.kwarg.arg)
    return names


def _public(name: str) -> bool:
    return not name.startswith('_')


def _check(problems: list[str], module: str, node, qualname: str, method: bool) -> None:
    params = _parameters(node, method)
    doc = ast.get_docstring(node) or ''
    missing = [p for p in params if p not in documented(doc)]
    if missing:
        problems.append(f'{module}:{qualname}: {", ".join(missing)}')


def undocumented() -> list[str]:
    """``module:function: missing`` for each public function missing a parameter."""
    problems = []
    for path in sorted(ROOT.rglob('*.py')):
        parts = path.relative_to(ROOT).with_suffix('').parts
        if any(p.startswith('_') and p != '__init__' for p in parts):
            continue
        module = '.'.join(parts)
        tree = ast.parse(path.read_text(), filename=str(path))

        for node in tree.body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and _public(node.name):
                _check(problems, module, node, node.name, method=False)
            elif isinstance(node, ast.ClassDef) and _public(node.name):
                class_doc = ast.get_docstring(node) or ''
                for item in node.body:
                    if not isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
                        continue
                    if item.name == '__init__':
                        params = _parameters(item, method=True)
                        missing = [p for p in params if p not in documented(class_doc)]
                        if missing:
                            problems.append(f'{module}:{node.name}: {", ".join(missing)}')
                    elif _public(item.name) and not any(
                        isinstance(d, ast.Name) and d.id in ('property', 'overload')
                        for d in item.decorator_list
                    ):
                        _check(problems, module, item, f'{node.name}.{item.name}', method=True)
    return problems


def test_public_functions_document_their_parameters():
    problems = undocumented()
    assert not problems, f'{len(problems)} undocumented parameters:\n' + '\n'.join(problems)


@pytest.mark.parametrize(
    'doc, names',
    [
        (
            'One line.\n\nParameters\n----------\na, b : int\n    Two.\n*args\n    More.\n',
            {'a', 'b', 'args'},
        ),
        ('One line.\n\nReturns\n-------\nx : int\n', set()),
        ('X.\n\nParameters\n----------\nc : float\n    C.\n\nReturns\n-------\nd : int\n', {'c'}),
    ],
)
def test_documented_reads_numpy_sections(doc, names):
    assert documented(doc) == names
