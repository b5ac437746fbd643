"""Running a study into a directory: the journal, a resume after a stop, and the figures."""

from __future__ import annotations

import json

import pytest

from maglev_ros.study import (
    Journal,
    SerialBackend,
    StudyError,
    StudyInterrupted,
    load_study,
    plot_study,
    read_table,
    run_study,
    study_from_mapping,
)


class _StopAfter(SerialBackend):
    """The serial back end, with a Ctrl-C after ``n`` runs."""

    def __init__(self, n: int):
        self.n = n

    def imap_unordered(self, fn, tasks):
        for i, row in enumerate(super().imap_unordered(fn, tasks)):
            if i == self.n:
                raise KeyboardInterrupt
            yield row


def test_a_stopped_study_keeps_its_rows_and_resumes_to_the_full_table(small_study, tmp_path):
    spec = load_study(small_study)
    out = tmp_path / 'out'
    with pytest.raises(StudyInterrupted) as stop:
        run_study(spec, out, _StopAfter(3))
    partial = stop.value.partial
    assert len(partial.rows) == 3 and partial.total == 8 and not partial.complete
    assert [r['run'] for r in read_table(partial.table)] == [0, 1, 2]
    with pytest.raises(StudyError, match=r'already holds a study: pass --resume'):
        run_study(spec, out, SerialBackend())
    done = run_study(spec, out, SerialBackend(), resume=True)
    assert done.complete and done.resumed == 3
    assert len(Journal(out / 'runs.jsonl').read()) == 8
    straight = run_study(spec, tmp_path / 'straight', SerialBackend())
    assert json.dumps(done.rows) == json.dumps(straight.rows)
    assert done.table.read_bytes() == straight.table.read_bytes()
    # every figure of the study, drawn from its rows
    paths = plot_study(spec, done.rows, out)
    names = sorted(p.name for p in paths)
    assert names == [
        'region_of_attraction.png',
        'success_vs_plant_polarization.png',
        'worst_runs.png',
    ]
    for p in paths:
        assert p.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n' and p.stat().st_size > 10_000


def test_resume_checks_the_study(small_study, tmp_path):
    spec = load_study(small_study)
    with pytest.raises(StudyError, match=r'holds no study to resume'):
        run_study(spec, tmp_path / 'none', SerialBackend(), resume=True)
    other = study_from_mapping({**spec.to_mapping(), 'seed': 99}, 'other.yaml')
    out = tmp_path / 'out'
    with pytest.raises(StudyInterrupted):
        run_study(other, out, _StopAfter(0))
    with pytest.raises(StudyError, match=r'holds a different study than .*small.yaml'):
        run_study(spec, out, SerialBackend(), resume=True)
