import numpy as np
import pytest

from maglev_ros.excitation import (
    apply_pattern,
    chirp,
    excitation,
    multisine,
    pattern_signals,
    prbs,
    random_binary,
)


def test_prbs_is_a_maximum_length_sequence():
    order = 7
    u = prbs(2**order - 1, amplitude=0.5, order=order, seed=3)
    assert set(np.unique(u)) == {-0.5, 0.5}
    assert np.sum(u > 0) == 2 ** (order - 1)  # one more one than zeros
    period = np.concatenate([u, u])
    circular = np.array([np.dot(u, period[k : k + u.size]) for k in range(1, u.size)])
    np.testing.assert_allclose(circular, -0.25, atol=1e-12)  # two-valued autocorrelation


def test_prbs_band_holds_bits_and_seed_changes_the_phase():
    u = prbs(400, band=(0.0, 0.25), seed=1)
    assert np.all(u[0::4] == u[3::4])
    assert not np.array_equal(prbs(400, seed=1), prbs(400, seed=2))
    np.testing.assert_array_equal(prbs(400, seed=1), prbs(400, seed=1))
    with pytest.raises(ValueError, match='band of a prbs must start at 0'):
        prbs(10, band=(0.1, 0.5))


def test_random_binary_band_limits_its_spectrum():
    u = random_binary(2**14, amplitude=2.0, band=(0.0, 0.1), seed=0)
    assert set(np.unique(u)) == {-2.0, 2.0}
    power = np.abs(np.fft.rfft(u)) ** 2
    f = np.linspace(0, 1, power.size)
    assert power[f < 0.1].sum() > 0.6 * power.sum()  # white: 0.1; sign() adds harmonics


def test_multisine_has_power_only_in_band():
    n = 1000
    u = multisine(n, amplitude=1.5, band=(0.1, 0.3), seed=4)
    assert np.abs(u).max() == pytest.approx(1.5)
    spectrum = np.abs(np.fft.rfft(u))
    f = 2 * np.arange(spectrum.size) / n
    inside = (f >= 0.1) & (f <= 0.3)
    assert spectrum[~inside].max() < 1e-9 * spectrum[inside].max()
    assert np.all(spectrum[inside] > 1e-3 * spectrum[inside].max())


def test_chirp_sweeps_the_band():
    u = chirp(4000, amplitude=0.3, band=(0.05, 0.5))
    assert np.abs(u).max() <= 0.3 + 1e-12
    crossings_start = np.sum(np.diff(np.sign(u[:400])) != 0)
    crossings_end = np.sum(np.diff(np.sign(u[-400:])) != 0)
    assert crossings_end > 4 * crossings_start


def test_antisymmetric_pairs_and_independent_channels():
    signals = excitation('prbs', 1023, channels=pattern_signals('pairs'), amplitude=0.4, seed=9)
    commands = apply_pattern(signals, 'pairs')
    np.testing.assert_array_equal(commands[:, 0], -commands[:, 1])  # +u on x+, -u on x-
    np.testing.assert_array_equal(commands[:, 2], -commands[:, 3])
    assert abs(np.corrcoef(commands[:, 0], commands[:, 2])[0, 1]) < 0.2
    x_only = apply_pattern(signals[:, :1], 'x_pair', offset=[0, 0, 0.1, 0.1])
    assert np.all(x_only[:, 2:] == 0.1)


@pytest.mark.parametrize(
    'call, match',
    [
        (lambda: excitation('noise', 10), 'signal must be one of prbs, random_binary'),
        (lambda: apply_pattern(np.zeros((5, 1)), 'pairs'), r"pattern 'pairs' takes 2 signal"),
        (lambda: apply_pattern(np.zeros((5, 1)), 'diagonal'), 'pattern must be one of'),
        (lambda: multisine(10, band=(0.5, 0.4)), 'band must be'),
        (lambda: chirp(0), 'length must be an integer >= 1, got 0'),
        (lambda: prbs(10, amplitude=-1.0), 'amplitude must be a finite number >= 0'),
    ],
)
def test_errors(call, match):
    with pytest.raises(ValueError, match=match):
        call()
