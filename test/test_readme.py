"""The README: short, its two commands true, each task's command on the page it links.

The blocks and their marks: see ``doc_blocks``. README command 1, the main job, runs
once per session (the ``main_job`` fixture); what it prints is compared with the
sample output on docs/lab.md (test/test_docs.py).
"""

import re

import pytest
from conftest import next_domain_id
from doc_blocks import README, ROOT, blocks, environment, mark_problem, run_blocks

INSTALL = 'python3 -m venv .venv && .venv/bin/pip install -e ".[ros]" && '
TEST_COMMAND = (
    'python3 -m venv .venv && .venv/bin/pip install -e ".[ros,test]" && .venv/bin/python -m pytest'
)
TASKS = (
    'simulate',
    'levitate',
    'record',
    'identify',
    'calibrate',
    'V2x board',
    'V4x board',
    'launch with ROS 2',
)
_ROW = re.compile(
    r'^\| (?P<task>[^|`]+) \| `(?P<command>[^`]+)` \| \[[^]]+\]\((?P<page>[^)]+)\) \|$'
)


def task_rows(text: str) -> list[re.Match]:
    return [m for line in text.splitlines() if (m := _ROW.match(line))]


def _flat(text: str) -> str:
    """Text with shell line continuations joined and runs of spaces collapsed."""
    return ' '.join(re.sub(r'\\\n', ' ', text).split())


def test_the_readme_is_at_most_200_lines():
    assert len(README.read_text().splitlines()) <= 200


def test_every_block_says_whether_it_runs():
    problems = [p for b in blocks(README, 'readme') if (p := mark_problem(b))]
    assert not problems, '\n'.join(problems)


def test_the_two_commands_are_the_ones_ci_and_users_run():
    two = [b.body.strip() for b in blocks(README, 'readme')[:2]]
    assert two[0] == INSTALL + '.venv/bin/maglev-lab --out lab --overwrite'
    assert two[1] == TEST_COMMAND
    ci = (ROOT / '.ci' / 'run').read_text()
    assert 'pip install -e ".[ros,test]"' in ci
    assert '.venv/bin/python -m pytest' in ci


def test_each_task_has_its_command_on_the_page_it_links():
    rows = task_rows(README.read_text())
    for task in TASKS:
        assert any(task in row['task'] for row in rows), f'README: no task row for {task!r}'
    for row in rows:
        page = ROOT / row['page']
        assert page.is_file() and page.parent == ROOT / 'docs', (
            f'README: the {row["task"].strip()!r} row links {row["page"]}, not a page in docs/'
        )
        assert _flat(row['command']) in _flat(page.read_text()), (
            f'README: the command of {row["task"].strip()!r} is not on {row["page"]}: '
            f'{row["command"]}'
        )


def test_the_site_home_has_the_same_tasks():
    readme = [(r['task'], r['command'], r['page']) for r in task_rows(README.read_text())]
    home = (ROOT / 'docs' / 'index.md').read_text()
    site = [(r['task'], r['command'], 'docs/' + r['page']) for r in task_rows(home)]
    assert site == readme


@pytest.mark.timeout(3600)
def test_readme_runs_as_written(main_job):
    lab = main_job.directory / 'lab'
    for name in ('models.json', 'compare_x.png', 'physics_x.png', 'compare_mimo.png'):
        assert (lab / name).is_file(), f'the main job wrote no {name}'
    assert (lab / 'bag' / 'metadata.yaml').is_file()
    # any later README block runs in the main job's directory, in order
    run_blocks(
        blocks(README, 'readme'), main_job.directory, environment(next_domain_id()), main_job
    )
