"""Runs of a study: grid order, seeds and draws depend only on the study and the run index."""

from __future__ import annotations

import pytest

from maglev_ros.study import StudyError, plan_runs, study_from_mapping

STUDY = {
    'duration': 0.5,
    'seed': 11,
    'repeats': 2,
    'grid': {'controller': ['lqr', 'pd'], 'x0.x': [0.0, 1e-3]},
    'random': {'plant.polarization': {'normal': {'mean': 0.0, 'std': 0.05}}},
}


def test_runs_cover_the_grid_times_repeats_in_order():
    tasks = plan_runs(study_from_mapping(STUDY))
    assert [t.index for t in tasks] == list(range(8))
    points = [(t.as_dict()['controller'], t.as_dict()['x0.x']) for t in tasks]
    assert points == [(c, x) for c in ('lqr', 'pd') for x in (0.0, 1e-3) for _ in range(2)]
    assert len({t.seed for t in tasks}) == 8
    assert len({t.as_dict()['plant.polarization'] for t in tasks}) == 8


def test_a_run_depends_only_on_the_base_seed_and_its_index():
    a = plan_runs(study_from_mapping(STUDY))
    b = plan_runs(
        study_from_mapping({**STUDY, 'grid': {**STUDY['grid'], 'x0.x': [0.0, 1e-3, 2e-3]}})
    )
    assert a[:4] == b[:4]  # the first grid point's runs are unchanged by a longer grid
    c = plan_runs(study_from_mapping({**STUDY, 'seed': 12}))
    assert all(x.seed != y.seed for x, y in zip(a, c, strict=True))
    assert plan_runs(study_from_mapping(STUDY)) == a


def test_a_draw_out_of_range_is_named():
    study = {**STUDY, 'random': {'sensor.noise': {'normal': {'mean': 1e-5, 'std': 1e-4}}}}
    with pytest.raises(
        StudyError, match=r'random.sensor.noise: run \d+ drew -[\d.e-]+, but it must be >= 0'
    ):
        plan_runs(study_from_mapping(study, 'f.yaml'))


def test_settings_that_do_not_fit_together_are_found_before_any_run():
    study = {
        'duration': 0.5,
        'fixed': {'estimator.magnet_strength': True},
        'grid': {'estimator': ['kf', 'ekf']},
    }
    with pytest.raises(
        StudyError,
        match=r'f.yaml: run 1 \(estimator.magnet_strength=True, estimator=ekf\): '
        r'magnet_strength is supported by the kf filter only',
    ):
        plan_runs(study_from_mapping(study, 'f.yaml'))
