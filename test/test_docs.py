"""The documentation site: it builds strictly, and every runnable block of every page runs.

The marks: see ``doc_blocks``. Each page's blocks run in order in a directory of
their own, where ``lab/`` is the main job's (README command 1, run once per
session); the main job's printed output is compared with docs/lab.md's sample
output within the tolerance the page states.
"""

import importlib
import inspect
import os
import re
import subprocess
import sys

import pytest
from conftest import next_domain_id
from doc_blocks import (
    DOCS,
    ROOT,
    Block,
    blocks,
    environment,
    mark_problem,
    pages,
    run_blocks,
    same_output,
)

RUNS = ('run', 'main-job', 'output')


def _page_id(path):
    return str(path.relative_to(DOCS))


def test_every_block_of_every_page_says_whether_it_runs():
    problems = [p for page in pages() for b in blocks(page, 'docs') if (p := mark_problem(b))]
    assert not problems, '\n'.join(problems)


def test_the_main_jobs_sample_output_is_on_the_lab_page():
    lab = blocks(DOCS / 'lab.md', 'docs')
    kinds = [b.kind for b in lab]
    assert 'main-job' in kinds
    assert kinds[kinds.index('main-job') + 1 :].count('output') >= 1


def test_the_site_builds_strictly(tmp_path):
    done = subprocess.run(
        [sys.executable, '-m', 'mkdocs', 'build', '--strict', '--site-dir', str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        env={**os.environ, 'NO_MKDOCS_2_WARNING': '1'},
    )
    assert done.returncode == 0, f'mkdocs build --strict failed:\n{done.stdout}\n{done.stderr}'
    assert (tmp_path / 'index.html').is_file()
    # every public class and function of every package with an API page is on it
    # (constants and type aliases are listed where documented)
    for page in sorted((DOCS / 'reference' / 'api').glob('*.md')):
        package = importlib.import_module(f'maglev_ros.{page.stem}')
        html = (tmp_path / 'reference' / 'api' / page.stem / 'index.html').read_text()
        ids = set(re.findall(r'id="(maglev_ros\.[\w.]+)"', html))
        missing = [
            name
            for name in package.__all__
            if (
                inspect.isclass(getattr(package, name))
                or inspect.isfunction(getattr(package, name))
            )
            and f'{package.__name__}.{name}' not in ids
            and not any(i.endswith(f'.{name}') and i.startswith(package.__name__) for i in ids)
        ]
        assert not missing, f'{page.name}: not on the API page: {missing}'


def test_a_broken_link_fails_the_strict_build(tmp_path):
    site = tmp_path / 'site'
    (site / 'docs').mkdir(parents=True)
    (site / 'docs' / 'index.md').write_text('# home\n\n[gone](missing.md)\n')
    (site / 'mkdocs.yml').write_text('site_name: t\nnav:\n  - index.md\n')
    done = subprocess.run(
        [sys.executable, '-m', 'mkdocs', 'build', '--strict'],
        cwd=site,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode != 0
    assert re.search(r'missing\.md', done.stdout + done.stderr)


@pytest.mark.timeout(3600)
@pytest.mark.parametrize(
    'page',
    [p for p in pages() if any(b.kind in RUNS for b in blocks(p, 'docs'))],
    ids=_page_id,
)
def test_page_runs_as_written(page, tmp_path, request):
    page_blocks = blocks(page, 'docs')
    needs_main_job = any(b.kind == 'main-job' for b in page_blocks) or any(
        'lab/' in b.body for b in page_blocks if b.kind == 'run'
    )
    main_job = request.getfixturevalue('main_job') if needs_main_job else None
    if main_job is not None:
        (tmp_path / 'lab').symlink_to(main_job.directory / 'lab', target_is_directory=True)
    ran = run_blocks(page_blocks, tmp_path, environment(next_domain_id()), main_job)
    assert ran >= 1


def _output_block(body, mark='output (within 5 % or 0.05)'):
    return Block(DOCS / 'lab.md', 1, mark, '', body)


def test_sample_output_is_compared_within_the_stated_tolerance():
    shown = _output_block(
        'fit 63.54 %, statistic 140.8\nrecorded (5.000 s simulated in 37.5 s, 0.13 x real time)\n'
    )
    same_output(
        'fit  63.60 %, statistic 146.0\n'
        'recorded (5.000 s simulated in 12.0 s, 0.42 x real time)\n',
        shown,
    )
    with pytest.raises(AssertionError, match=r'160\.0 is not 140\.8 within 5 % or 0\.05'):
        same_output(
            'fit 63.54 %, statistic 160.0\nrecorded (5.000 s simulated in 1 s, 5 x real time)\n',
            shown,
        )
    with pytest.raises(AssertionError, match='the text differs'):
        same_output(
            'fit 63.54 %, statistics 140.8\nrecorded (5.000 s simulated in 1 s, 5 x real time)\n',
            shown,
        )
    with pytest.raises(AssertionError, match='2 lines shown, the run printed 1'):
        same_output('fit 63.54 %, statistic 140.8\n', shown)


def test_a_block_without_a_mark_or_a_reason_is_named():
    block = Block(DOCS / 'lab.md', 7, '', 'sh', 'maglev-lab --out lab\n')
    assert mark_problem(block) == "docs/lab.md line 7: unmarked block 'maglev-lab --out lab\\n'"
    assert 'skip needs a reason' in mark_problem(Block(DOCS / 'lab.md', 7, 'skip', 'sh', 'x'))
    assert 'states its tolerance' in mark_problem(_output_block('x', mark='output'))
    assert mark_problem(Block(DOCS / 'lab.md', 7, 'run (exits 1: why)', 'sh', 'x')) is None


def test_the_launch_files_and_executables_named_exist():
    """Every ``ros2 launch maglev_ros FILE`` and ``ros2 run maglev_ros EXE`` of the docs."""
    setup = (ROOT / 'setup.py').read_text()
    launch = {p.name for p in (ROOT / 'launch').glob('*.launch.xml')}
    problems = []
    for page in [ROOT / 'README.md', *pages()]:
        text = page.read_text()
        for name in re.findall(r'ros2 launch maglev_ros ([\w.]+\.launch\.xml)', text):
            if name not in launch:
                problems.append(f'{page.name}: no launch file {name}')
        for exe in re.findall(r'ros2 run maglev_ros (\w+)', text):
            if f"'{exe}'" not in setup:
                problems.append(f'{page.name}: no executable {exe}')
    assert not problems, '\n'.join(sorted(set(problems)))
