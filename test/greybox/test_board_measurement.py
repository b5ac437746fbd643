"""Dynamic calibration of a board whose firmware processes the field (V4x PC control)."""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from maglev_ros.greybox import (
    GreyBoxError,
    LinearGreyBoxProblem,
    assess,
    calibrate_dynamic,
    noise_level,
)
from maglev_ros.physics import MaggyModel
from maglev_ros.physics.board_processing import BoardProcessing

from .levitation import TRUTH, levitation_record, nominal_vector, plant_parameters

FREE = ('magnet.mass', 'magnet.polarization')


@lru_cache(maxsize=1)
def processed_record():
    """The levitation record as the firmware would report it (the plant's own baseline)."""
    exp, _ = levitation_record()
    board = BoardProcessing.from_model(MaggyModel(plant_parameters()))
    return replace(exp, y=board.apply(exp.y, exp.u, exp.Ts), name='processed levitation')


def test_the_board_model_recovers_mass_and_polarization():
    cal = calibrate_dynamic(
        nominal_vector().with_free(FREE), [processed_record()], measurement='board'
    )
    for name in FREE:
        true, est, sd = TRUTH[name], cal.estimate[name], cal.std[name]
        assert abs(est - true) <= 3 * sd, (name, est, true, sd)
        assert abs(est - true) <= 0.01 * abs(true), (name, est, true)
    assert cal.validation_calibrated[0].total_rms < cal.validation_nominal[0].total_rms
    # with the baseline removed, mass and polarisation are strongly correlated: said so
    verdict = assess(cal)
    assert verdict.status in ('calibrated', 'partly calibrated')
    assert all('correlated' in w for w in verdict.warnings), verdict.warnings


def test_the_board_models_predictor_leaves_white_innovations_on_the_filtered_axes():
    """The sensor noise enters before the board's filter: the predictor of the true
    parameters takes it as noise of the filter states, and what it cannot predict is
    white. (Taken as white noise of the readings, the x and y innovations correlate
    0.85 from one sample to the next, and in closed loop the fit is biased.)"""
    exp = processed_record()
    problem = LinearGreyBoxProblem(
        nominal_vector().with_free(FREE), [exp], 1, noise_level(exp.y), measurement='board'
    )
    [eps] = problem.errors(TRUTH)
    eps = eps - eps.mean(axis=0)
    lag1 = np.sum(eps[1:] * eps[:-1], axis=0) / np.sum(eps * eps, axis=0)
    assert np.all(np.abs(lag1) < 0.05), lag1


def test_the_raw_model_on_processed_data_is_not_calibrated():
    cal = calibrate_dynamic(nominal_vector().with_free(FREE), [processed_record()])
    verdict = assess(cal)
    assert verdict.status == 'not calibrated' and verdict.exit_status == 1
    assert any('bound' in w or 'worse' in w for w in verdict.warnings), verdict.warnings


def test_the_nonlinear_form_refuses_the_board_model():
    with pytest.raises(GreyBoxError, match='nonlinear form models the raw field only'):
        calibrate_dynamic(
            nominal_vector().with_free(FREE),
            [processed_record()],
            measurement='board',
            form='nonlinear',
        )


def test_a_diverging_nonlinear_predictor_is_named_with_its_count_and_time():
    # the raw model's nonlinear predictor on processed data (tens of mT off): it diverges
    # in the burn-in; that is the error, not "not identifiable, rank 0"
    with pytest.raises(GreyBoxError, match=r'diverged in 1 of \d+ evaluations') as info:
        calibrate_dynamic(nominal_vector().with_free(FREE), [processed_record()], form='nonlinear')
    assert 'in the burn-in' in str(info.value) and 't = 0.00' in str(info.value)
    assert '--measurement' in str(info.value)
