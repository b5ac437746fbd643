"""Confidence bands: Monte Carlo coverage of the true responses, shapes, refusals."""

import numpy as np
import pytest
from scipy.signal import freqz, lfilter

from maglev_ros.sysid import armax, arx
from maglev_ros.sysid.confidence import frequency_band, simulation_band, step_band

from .systems import A2, B2, C_ARMAX, TS, simulate_siso

RUNS = 300
F = np.linspace(5.0, 2400.0, 12)  # Hz, below Nyquist (2500 Hz)


def coverage(sigma):
    """Fractions of (run, frequency) and (run, sample) where the truth is inside the band."""
    _, h = freqz(B2, A2, worN=F, fs=1 / TS)
    true_mag = 20 * np.log10(np.abs(h))
    true_step = lfilter(B2, A2, np.ones(40))
    inside_mag, inside_phase, inside_step = [], [], []
    for run in range(RUNS):
        model = arx(simulate_siso(400, seed=1000 + run, noise=0.5), 2, 2, 1)
        mag, phase = frequency_band(model, F, sigma)
        inside_mag.append(mag.contains(true_mag[:, None, None]))
        delta = np.degrees(np.angle(h / model.freqresp(F)[:, 0, 0]))
        inside_phase.append(np.abs(delta) <= sigma * phase.std[:, 0, 0])
        inside_step.append(step_band(model, 40, sigma).contains(true_step[:, None, None])[1:])
    return np.mean(inside_mag), np.mean(inside_phase), np.mean(inside_step)


def test_three_sigma_bands_hold_the_truth_at_the_expected_rate():
    """3 sigma: 99.73 % expected; 1 sigma: 68.3 % (so the bands are not just wide)."""
    for value in coverage(3.0):
        assert value > 0.985
    for value in coverage(1.0):
        assert 0.60 < value < 0.76


def test_bands_shrink_with_data_and_work_for_armax():
    short = arx(simulate_siso(500, seed=1), 2, 2, 1)
    long = arx(simulate_siso(8000, seed=1), 2, 2, 1)
    ratio = frequency_band(short, F)[0].std / frequency_band(long, F)[0].std
    assert np.allclose(ratio, 4.0, rtol=0.3)  # std ~ 1 / sqrt(N)
    data = simulate_siso(3000, seed=2, C=C_ARMAX)
    model = armax(data, 2, 2, 1, 1)
    band = simulation_band(model, data.u[:200])
    assert band.value.shape == band.std.shape == (200, 1)
    assert np.all(band.upper >= band.lower) and band.std[50:].min() > 0


def test_no_covariance_is_refused():
    model = arx(simulate_siso(500, seed=1), 2, 2, 1)
    bare = type(model)(model.structure, model.orders, model.theta, model.Ts, [[1.0]])
    with pytest.raises(ValueError, match='no parameter covariance'):
        step_band(bare, 10)
