"""Feedback detection on closed loops around the simulated Maggy plant and on open-loop data."""

import numpy as np
import pytest

from maglev_ros.sysid.feedback import ADVICE, detect_feedback

from .closed_loop import simulate_loop
from .maglev_loop import simulate
from .systems import lab_second_order, simulate_siso


@pytest.mark.parametrize('excitation', [0.0, 0.5])
def test_the_maglev_loop_is_closed_loop(excitation):
    data, _ = simulate(6000, 1, excitation)
    test = detect_feedback(data)
    assert test.closed_loop and test.pairs == (('Bx_0', 'ux'),)
    assert test.statistic[0, 0] > 2 * test.limit
    assert test.summary().startswith('closed loop: ux reacts to Bx_0')
    assert test.as_dict()['advice'] == ADVICE and '--instruments' in ADVICE
    # without excitation the input is the controller's output alone: not informative
    assert test.informative == (excitation > 0)
    if excitation:
        assert test.excitation_share[0] > 0.3
    else:
        assert test.excitation_share[0] < 0.01 and 'no external excitation' in test.summary()


def test_a_static_gain_in_the_loop_is_found():
    data, _ = simulate_loop(8000, 1)
    assert detect_feedback(data).closed_loop


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_open_loop_data_are_not_flagged(seed):
    # a held PRBS (coloured input) and white output noise, and white input with ARX noise
    for data in (lab_second_order(seed=seed).detrend(), simulate_siso(8000, seed, noise=0.5)):
        test = detect_feedback(data)
        assert not test.closed_loop, test.summary()
        assert test.informative and 'no feedback detected' in test.summary()


def test_too_short_or_no_input_is_refused():
    data, _ = simulate_loop(80, 1)
    with pytest.raises(ValueError, match='too few to test 25 lags'):
        detect_feedback(data)
    with pytest.raises(ValueError, match='at least one input'):
        detect_feedback(data.select(inputs=[]))
    assert np.isfinite(detect_feedback(data, max_lag=5, order=2).statistic).all()
