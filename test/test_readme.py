"""The README runs as written: its code blocks, in order, in a fresh directory.

Every fenced block is preceded by an HTML comment ``<!-- readme: MARK -->``:

* ``run``: a shell block (run with ``bash -e``) or a Python block (run with this
  interpreter), from the directory of the earlier blocks; it must exit 0, or with
  the status its mark names (``run (exits 1: why)``: then the last command's);
* ``run-after-install``: the first "Two commands" block; its install part is what
  created this environment, the command after the last ``&&`` is run;
* ``output ...``: what that command prints (compared line by line; the timing in
  the "recorded" line may differ);
* ``file NAME``: written to ``NAME`` for the blocks after it;
* ``skip (reason)``: not run, for the reason given.

The ``maglev-*`` commands are found on ``PATH`` (this interpreter's ``bin``), as
after ``. .venv/bin/activate``.
"""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / 'README.md'
# fences may be indented (a block inside a list item), its marker then indented alike
BLOCK = re.compile(
    r'(?:<!-- readme: (?P<mark>[^\n]*?) -->\n[ \t]*)?```(?P<lang>\w*)\n(?P<body>.*?)^[ \t]*```',
    re.S | re.M,
)
MARKS = ('run', 'run-after-install', 'output', 'file', 'skip')
TIMEOUT = 900  # s per block: the main job takes 10-80 s, the accurate model 10-30 s


def blocks():
    return [
        (m['mark'] or '', m['lang'], m['body'], README.read_text()[: m.start()].count('\n') + 1)
        for m in BLOCK.finditer(README.read_text())
    ]


def test_every_block_says_whether_it_runs():
    for mark, _, body, line in blocks():
        assert mark.split(' ')[0] in MARKS, f'README line {line}: unmarked block {body[:60]!r}'
        if mark.startswith('skip'):
            assert re.fullmatch(r'skip \(.+\)', mark), f'README line {line}: skip needs a reason'


def _environment():
    env = dict(os.environ)
    env['PATH'] = os.pathsep.join([str(Path(sys.executable).parent), env.get('PATH', '')])
    env.setdefault('OPENBLAS_NUM_THREADS', '1')
    env['ROS_DOMAIN_ID'] = '101'
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def _run(cmd, cwd, env, line, status=0):
    done = subprocess.run(
        cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT, check=False
    )
    assert done.returncode == status, (
        f'README block at line {line} exited {done.returncode}, not {status}:\n'
        f'{done.stdout}\n{done.stderr}'
    )
    return done


def _status(mark: str) -> int:
    """The exit status a ``run`` mark names (``run (exits 1: why)``), else 0."""
    named = re.match(r'run \(exits (\d+): .+\)$', mark)
    return int(named[1]) if named else 0


def _same_output(printed: str, expected: str, line: int) -> None:
    timing = re.compile(r'simulated in [0-9.]+ s, [0-9.]+ x real time')
    got = [timing.sub('TIMING', t.rstrip()) for t in printed.splitlines() if t.strip()]
    want = [timing.sub('TIMING', t.rstrip()) for t in expected.splitlines() if t.strip()]
    assert got == want, f'README line {line}: the sample output differs from a run:\n{printed}'


@pytest.mark.timeout(3600)
def test_readme_runs_as_written(tmp_path):
    env = _environment()
    printed = None
    for mark, lang, body, line in blocks():
        kind = mark.split(' ')[0]
        if kind == 'file':
            (tmp_path / mark.split(' ')[1]).write_text(body)
        elif kind == 'run-after-install':
            command = body.strip().split('&& ')[-1].replace('.venv/bin/', '')
            printed = _run(['bash', '-e', '-c', command], tmp_path, env, line).stdout
        elif kind == 'output':
            assert printed is not None, f'README line {line}: output block before its command'
            _same_output(printed, body, line)
        elif kind == 'run' and lang == 'python':
            _run([sys.executable, '-c', body], tmp_path, env, line)
        elif kind == 'run':
            assert lang in ('sh', 'bash'), f'README line {line}: cannot run a {lang!r} block'
            status = _status(mark)  # a block of several such commands: the last one's
            _run(['bash', '-e' if status == 0 else '+e', '-c', body], tmp_path, env, line, status)
    assert (tmp_path / 'plots' / 'x' / 'compare.png').is_file()
    assert (tmp_path / 'lab_board' / 'models.json').is_file()
