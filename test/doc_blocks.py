"""The fenced blocks of the README and the docs pages, and how the tests run them.

Every fenced block is preceded by an HTML comment ``<!-- PREFIX: MARK -->``
(``readme`` in the README, ``docs`` in the pages under docs/):

* ``run``: a shell block (run with ``bash -e``) or a Python block (run with this
  interpreter), from the directory of the earlier blocks of the page; it must
  exit 0, or with the status its mark names (``run (exits 1: why)``: then the
  last command's);
* ``run-after-install`` (README): the first "Two commands" block; its install
  part is what created this environment, the command after the last ``&&`` is
  the main job (:func:`run_main_job`);
* ``main-job`` (a page): that same command, shown on its page; what it printed
  is compared with the next ``output`` block;
* ``output (within R % or A; ...)``: what the command before it prints: the same
  text (runs of spaces aside) and every number within ``R`` % or ``A``,
  whichever is larger; the wall-clock timing of a "recorded" line is not compared;
* ``file NAME``: written to ``NAME`` for the blocks after it;
* ``skip (reason)``: not run, for the reason given.

The ``maglev-*`` commands are found on ``PATH`` (this interpreter's ``bin``), as
after ``. .venv/bin/activate``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / 'README.md'
DOCS = ROOT / 'docs'
MARKS = ('run', 'run-after-install', 'main-job', 'output', 'file', 'skip')
TIMEOUT = 900  # s per block: the main job takes 1-3 minutes, a first run more
# fences may be indented (a block inside a list item), its mark then indented alike
_BLOCK = (
    r'(?:<!-- {prefix}: (?P<mark>[^\n]*?) -->\n[ \t]*)?'
    r'```(?P<lang>\w*)\n(?P<body>.*?)^[ \t]*```'
)
_TIMING = re.compile(r'simulated in [0-9.]+ s, [0-9.]+ x real time')
_NUMBER = re.compile(r'[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?')
_TOLERANCE = re.compile(r'within ([0-9.]+) % or ([0-9.eE+-]+)')


@dataclass(frozen=True)
class Block:
    """One fenced block: its mark, language, body and where it is."""

    path: Path
    line: int
    mark: str
    lang: str
    body: str

    @property
    def kind(self) -> str:
        return self.mark.split(' ')[0]

    @property
    def where(self) -> str:
        return f'{self.path.relative_to(ROOT)} line {self.line}'


def blocks(path: Path, prefix: str) -> list[Block]:
    """The fenced blocks of ``path`` with their ``<!-- prefix: ... -->`` marks."""
    text = path.read_text()
    pattern = re.compile(_BLOCK.format(prefix=prefix), re.S | re.M)
    return [
        Block(
            path,
            text[: m.start()].count('\n') + 1,
            m['mark'] or '',
            m['lang'],
            textwrap.dedent(m['body']),
        )
        for m in pattern.finditer(text)
    ]


def pages() -> list[Path]:
    """Every Markdown page of the site."""
    return sorted(DOCS.rglob('*.md'))


def mark_problem(block: Block) -> str | None:
    """What is wrong with a block's mark, or None."""
    if block.kind not in MARKS:
        return f'{block.where}: unmarked block {block.body[:60]!r}'
    if block.kind == 'skip' and not re.fullmatch(r'skip \(.+\)', block.mark):
        return f'{block.where}: skip needs a reason: skip (why)'
    if (
        block.kind == 'run'
        and block.mark != 'run'
        and not re.fullmatch(r'run \(exits \d+: .+\)', block.mark)
    ):
        return f'{block.where}: write run, or run (exits N: why)'
    if block.kind == 'output' and not _TOLERANCE.search(block.mark):
        return f'{block.where}: an output mark states its tolerance: output (within R % or A)'
    if block.kind == 'file' and len(block.mark.split(' ')) < 2:
        return f'{block.where}: file needs a name: file NAME'
    if block.kind == 'run' and block.lang not in ('sh', 'bash', 'python'):
        return f'{block.where}: cannot run a {block.lang!r} block'
    return None


def environment(domain_id: int) -> dict[str, str]:
    """The blocks' environment: this venv's commands first, a ROS domain of their own."""
    env = dict(os.environ)
    env['PATH'] = os.pathsep.join([str(Path(sys.executable).parent), env.get('PATH', '')])
    env.setdefault('OPENBLAS_NUM_THREADS', '1')
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONPATH'] = os.pathsep.join(p for p in (str(ROOT), env.get('PYTHONPATH', '')) if p)
    return env


def run(cmd: list[str], cwd: Path, env: dict[str, str], where: str, status: int = 0) -> str:
    """Run ``cmd``; return its standard output, asserting its exit status."""
    done = subprocess.run(
        cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=TIMEOUT, check=False
    )
    assert done.returncode == status, (
        f'{where}: the block exited {done.returncode}, not {status}:\n{done.stdout}\n{done.stderr}'
    )
    return done.stdout


def main_job_command() -> str:
    """README command 1 without its install part (the main job)."""
    first = [b for b in blocks(README, 'readme') if b.kind == 'run-after-install']
    assert len(first) == 1, 'README: one block is marked run-after-install'
    return first[0].body.strip().split('&& ')[-1].replace('.venv/bin/', '')


@dataclass(frozen=True)
class MainJob:
    """The main job's run: its directory and what it printed."""

    directory: Path
    printed: str


def run_main_job(directory: Path, domain_id: int) -> MainJob:
    """Run README command 1's main job in ``directory``."""
    printed = run(
        ['bash', '-e', '-c', main_job_command()],
        directory,
        environment(domain_id),
        'README command 1',
    )
    return MainJob(directory, printed)


def _status(mark: str) -> int:
    named = re.match(r'run \(exits (\d+): .+\)$', mark)
    return int(named[1]) if named else 0


def _normal(line: str) -> str:
    return ' '.join(_TIMING.sub('TIMING', line).split())


def same_output(printed: str, block: Block) -> None:
    """Assert that ``printed`` matches an ``output`` block within its stated tolerance."""
    found = _TOLERANCE.search(block.mark)
    relative, absolute = float(found[1]) / 100.0, float(found[2])
    got = [_normal(t) for t in printed.splitlines() if t.strip()]
    want = [_normal(t) for t in block.body.splitlines() if t.strip()]
    assert len(got) == len(want), (
        f'{block.where}: {len(want)} lines shown, the run printed {len(got)}:\n{printed}'
    )
    for number, (g, w) in enumerate(zip(got, want, strict=True), 1):
        assert _NUMBER.sub('#', g) == _NUMBER.sub('#', w), (
            f'{block.where}, output line {number}: the text differs:\n  shown:   {w}\n'
            f'  printed: {g}'
        )
        for a, b in zip(_NUMBER.findall(g), _NUMBER.findall(w), strict=True):
            assert abs(float(a) - float(b)) <= max(absolute, relative * abs(float(b))), (
                f'{block.where}, output line {number}: {a} is not {b} within '
                f'{found[1]} % or {found[2]}:\n  shown:   {w}\n  printed: {g}'
            )


def run_blocks(
    page: list[Block], cwd: Path, env: dict[str, str], main_job: MainJob | None = None
) -> int:
    """Run a page's blocks in order in ``cwd``; return how many ran or were compared."""
    printed = None
    done = 0
    for block in page:
        if block.kind == 'file':
            (cwd / block.mark.split(' ')[1]).write_text(block.body)
        elif block.kind in ('main-job', 'run-after-install'):
            assert main_job is not None, f'{block.where}: the main job was not run'
            printed = main_job.printed
        elif block.kind == 'output':
            assert printed is not None, f'{block.where}: output block before its command'
            same_output(printed, block)
            done += 1
        elif block.kind == 'run' and block.lang == 'python':
            printed = run([sys.executable, '-c', block.body], cwd, env, block.where)
            done += 1
        elif block.kind == 'run':
            status = _status(block.mark)
            flags = '-e' if status == 0 else '+e'
            printed = run(['bash', flags, '-c', block.body], cwd, env, block.where, status)
            done += 1
    return done
