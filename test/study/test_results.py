"""Tables and the journal keep every value exactly; the summary and the intervals."""

from __future__ import annotations

import json
import math

import pytest

from maglev_ros.study import Journal, read_table, summary, write_table
from maglev_ros.study.results import columns, wilson_interval

ROWS = [
    {
        'run': 1,
        'seed': 7,
        'controller': 'pd',
        'x0.x': 0.1 + 0.2,
        'success': False,
        'outcome': 'crashed',
        'rms_x': math.nan,
        'reason': 'touched the base at t = 0.2 s',
    },
    {
        'run': 0,
        'seed': 5,
        'controller': 'lqr',
        'x0.x': 1e-3 / 3,
        'success': True,
        'outcome': 'ok',
        'rms_x': 2.5e-5,
        'reason': '',
    },
]
COLS = ['run', 'seed', 'controller', 'x0.x', 'success', 'outcome', 'rms_x', 'reason']


@pytest.mark.parametrize('fmt', ['csv', 'parquet'])
def test_a_table_reads_back_exactly_in_run_order(tmp_path, fmt):
    path = write_table(ROWS, COLS, tmp_path / 'results', fmt)
    assert path.name == f'results.{fmt}'
    back = read_table(path)
    assert [r['run'] for r in back] == [0, 1]
    assert json.dumps(back) == json.dumps(sorted(ROWS, key=lambda r: r['run']))
    assert list(back[0]) == COLS
    assert write_table(ROWS[::-1], COLS, tmp_path / 'again', fmt).read_bytes() == path.read_bytes()


def test_the_journal_ignores_a_line_cut_short(tmp_path):
    journal = Journal(tmp_path / 'runs.jsonl')
    assert journal.read() == {}
    for row in ROWS:
        journal.append(row)
    with open(journal.path, 'a') as stream:
        stream.write('{"run": 2, "se')
    rows = journal.read()
    assert sorted(rows) == [0, 1]
    assert json.dumps(rows[1]) == json.dumps(ROWS[0])


def test_columns_and_summary():
    assert columns(['x0.x'])[:3] == ['run', 'seed', 'x0.x']
    text = summary(ROWS, ['controller'], 4)
    assert text.splitlines()[0] == '2 of 4 runs done; success 1/2 (50.0 %)'
    assert 'outcomes: ok 1, crashed 1' in text
    assert 'controller: pd: 0 %, lqr: 100 %' in text


def test_wilson_interval():
    low, high = wilson_interval(10, 10)
    assert high == 1.0 and 0.69 < low < 0.73  # the textbook 0.722
    low, high = wilson_interval(0, 3)
    assert low == 0.0 and 0.55 < high < 0.57
    assert wilson_interval(0, 0) == (0.0, 1.0)
