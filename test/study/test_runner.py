"""Judging a run: crash, leaving the bounds, not settling, success -- on real runs."""

from __future__ import annotations

import math

import pytest

from maglev_ros.study import plan_runs, run_task, study_from_mapping
from maglev_ros.study.loop_adapter import simulate
from maglev_ros.study.runner import judge
from maglev_ros.study.spec import SuccessCriterion


def test_outcomes_of_real_runs():
    result = simulate({'controller': 'pd', 'x0.x': 0.3e-3}, 1, 0.4)
    assert not result.crashed
    loose = judge(result, 0.4, SuccessCriterion(bound=3e-3, window=0.1, rms=5e-4))
    assert loose['outcome'] == 'ok' and loose['success']
    assert math.isclose(loose['max_excursion'], 0.3e-3, rel_tol=0.2)
    assert 0 < loose['peak_current'] <= 1.0 + 1e-9
    assert (
        judge(result, 0.4, SuccessCriterion(bound=0.1e-3, window=0.1, rms=5e-4))['outcome']
        == 'left_bounds'
    )
    assert (
        judge(result, 0.4, SuccessCriterion(bound=3e-3, window=0.1, rms=1e-7))['outcome']
        == 'not_settled'
    )
    crash = simulate({'controller': 'pd', 'x0.x': 2.0e-3}, 1, 0.4)
    verdict = judge(crash, 0.4, SuccessCriterion())
    assert crash.crashed and verdict['outcome'] == 'crashed' and not verdict['success']
    assert 0 < verdict['crash_time'] < 0.4 and verdict['reason'] == crash.reason
    assert math.isnan(verdict['rms_x'])


def test_a_row_holds_run_seed_values_and_metrics():
    spec = study_from_mapping(
        {'duration': 0.05, 'fixed': {'controller': 'pd'}, 'grid': {'x0.x': [0.0]}}
    )
    (task,) = plan_runs(spec)
    row = run_task(task)
    assert list(row)[:4] == ['run', 'seed', 'controller', 'x0.x']
    assert row['run'] == 0 and row['seed'] == task.seed and row['controller'] == 'pd'


@pytest.mark.filterwarnings('ignore::RuntimeWarning')  # scipy, on the absurd weight
def test_a_loop_that_cannot_be_built_is_an_error_row():
    spec = study_from_mapping(
        {'duration': 0.05, 'fixed': {'controller': 'lqr', 'controller.position_scale': 1e-30}}
    )
    (task,) = plan_runs(spec)
    row = run_task(task)
    assert row['outcome'] == 'error' and not row['success']
    assert row['reason'].startswith('LQR design failed')


def test_a_controller_that_gave_up_is_no_success_even_with_the_magnet_still():
    # V4's equilibrium moves 3.1 mm with a 20 % stronger magnet: the LQR declares the
    # magnet lost at once and the magnet rests, exactly still, at the plant's equilibrium
    result = simulate({'params': 'maggy_v4', 'plant.polarization': 0.2}, 5, 0.1)
    verdict = judge(result, 0.1, SuccessCriterion(window=0.05))
    assert verdict['max_excursion'] < 1e-9  # it would pass on the position alone
    assert verdict['outcome'] == 'controller_off' and not verdict['success']
    assert verdict['reason'].startswith('controller ERROR: magnet lost')
