"""One-line descriptions of YAML errors that keep the line and column.

PyYAML's messages span several lines (context, problem, a snippet with a
caret); the command-line tools print one line, which used to be the context
alone ("while parsing a block mapping") without the position.
"""

from __future__ import annotations

import yaml

__all__ = ['yaml_error_text']


def yaml_error_text(err: yaml.YAMLError) -> str:
    """Describe a YAML error on one line: ``line L, column C: problem (context)``.

    Parameters
    ----------
    err : yaml.YAMLError
        The error raised by ``yaml.safe_load``.

    Returns
    -------
    str
        One line; line and column counted from 1 when PyYAML knows them.
    """
    mark = getattr(err, 'problem_mark', None) or getattr(err, 'context_mark', None)
    problem = getattr(err, 'problem', None) or ' '.join(str(err).split())
    context = getattr(err, 'context', None)
    where = f'line {mark.line + 1}, column {mark.column + 1}: ' if mark is not None else ''
    return f'{where}{problem}' + (f' ({context})' if context else '')
