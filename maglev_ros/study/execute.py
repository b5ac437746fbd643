"""Run a study into a results directory, resumable.

The directory holds ``study.yaml`` (the study as run, to check a resume
against), ``runs.jsonl`` (the journal: each finished run at once), and,
when the runs end or are interrupted, the table of the runs done.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from .parameters import StudyError
from .results import Journal, columns, write_table
from .runner import run_task
from .sampling import RunTask, plan_runs
from .spec import StudySpec, study_from_mapping

__all__ = ['StudyInterrupted', 'StudyRun', 'run_study', 'STUDY_FILE', 'JOURNAL_FILE', 'TABLE_STEM']

STUDY_FILE = 'study.yaml'
JOURNAL_FILE = 'runs.jsonl'
TABLE_STEM = 'results'


@dataclass
class StudyRun:
    """A study's rows after :func:`run_study`.

    Attributes
    ----------
    spec : StudySpec
    rows : list of dict
        Finished rows, in run order.
    total : int
        Runs in the study.
    resumed : int
        Rows that were already in the journal.
    table : Path
        The table file written.
    """

    spec: StudySpec
    rows: list[dict[str, Any]]
    total: int
    resumed: int
    table: Path

    @property
    def complete(self) -> bool:
        """Whether every run is done."""
        return len(self.rows) == self.total


class StudyInterrupted(KeyboardInterrupt):
    """The study was interrupted; its finished rows are kept.

    Parameters
    ----------
    partial : StudyRun
        The runs done, their table already written.
    """

    def __init__(self, partial: StudyRun):
        super().__init__(f'{len(partial.rows)} of {partial.total} runs done')
        self.partial = partial


def prepare(spec: StudySpec, out: Path, resume: bool) -> dict[int, dict[str, Any]]:
    """Create or check the results directory; return the rows already done.

    Parameters
    ----------
    spec : StudySpec
    out : Path
    resume : bool

    Raises
    ------
    StudyError
        ``out`` holds another study, or holds this one without ``resume``,
        or ``resume`` with nothing to resume.
    """
    stored = out / STUDY_FILE
    if stored.exists():
        if not resume:
            raise StudyError(
                f'{out} already holds a study: pass --resume to continue it, or choose '
                'another --out'
            )
        with open(stored, encoding='utf-8') as stream:
            previous = study_from_mapping(yaml.safe_load(stream), str(stored))
        if previous.fingerprint() != spec.fingerprint():
            raise StudyError(
                f'{out} holds a different study than {spec.source} (compare with {stored}): '
                'resume with the same file, or choose another --out'
            )
        return Journal(out / JOURNAL_FILE).read()
    if resume:
        raise StudyError(f'--resume: {out} holds no study to resume (no {STUDY_FILE})')
    out.mkdir(parents=True, exist_ok=True)
    tmp = stored.with_name(STUDY_FILE + '.tmp')
    with open(tmp, 'w', encoding='utf-8') as stream:
        yaml.safe_dump(spec.to_mapping(), stream, sort_keys=False)
    os.replace(tmp, stored)
    return {}


def run_study(
    spec: StudySpec,
    out: str | os.PathLike,
    backend,
    resume: bool = False,
    on_row: Callable[[dict[str, Any]], None] | None = None,
    on_start: Callable[[int, int], None] | None = None,
) -> StudyRun:
    """Run every run of a study not yet done; write the journal as runs finish and the table.

    Parameters
    ----------
    spec : StudySpec
    out : path
        Results directory.
    backend : SerialBackend or DaskBackend
        Where the runs are done.
    resume : bool
        Continue the study already in ``out``.
    on_row : callable, optional
        Called with each finished row (progress).
    on_start : callable, optional
        ``on_start(done, total)`` before the first new run.

    Returns
    -------
    StudyRun

    Raises
    ------
    StudyError
        See :func:`prepare` and :func:`~maglev_ros.study.sampling.plan_runs`.
    StudyInterrupted
        On Ctrl-C (SIGINT): the table of the finished runs is written first.
    """
    out = Path(out)
    tasks = plan_runs(spec)
    done = prepare(spec, out, resume)
    by_index = {t.index: t for t in tasks}
    for index, row in done.items():
        task = by_index.get(index)
        if task is None or task.seed != row['seed']:
            raise StudyError(f'{out / JOURNAL_FILE}: run {index} does not belong to this study')
    resumed = len(done)
    todo: list[RunTask] = [t for t in tasks if t.index not in done]
    journal = Journal(out / JOURNAL_FILE)
    cols = columns(spec.keys)
    if on_start is not None:
        on_start(resumed, len(tasks))
    rows = dict(done)

    def finish() -> StudyRun:
        ordered = [rows[i] for i in sorted(rows)]
        table = write_table(ordered, cols, out / TABLE_STEM)
        return StudyRun(spec, ordered, len(tasks), resumed, table)

    try:
        for row in backend.imap_unordered(run_task, todo):
            journal.append(row)
            rows[row['run']] = row
            if on_row is not None:
                on_row(row)
    except KeyboardInterrupt:
        rows.update(journal.read())  # a row may be in the journal and not yet here
        raise StudyInterrupted(finish()) from None
    return finish()
