import numpy as np
import pytest

from maglev_ros.sysid import IdData, merge


def sine_data(freqs, N=4000, Ts=1e-3):
    t = np.arange(N) * Ts
    y = sum(np.sin(2 * np.pi * f * t) for f in freqs)
    return IdData(y, y.copy(), Ts, ['Bx'], ['Ix'], ['mT'], ['A'])


def test_constructor_shapes_names_units():
    d = IdData(np.zeros((10, 2)), np.zeros(10), 0.5, ['bx', 'by'], ['ix'], ['mT', 'mT'], ['A'])
    assert (d.N, d.ny, d.nu, d.Ts) == (10, 2, 1, 0.5)
    assert d.output_names == ('bx', 'by') and d.input_units == ('A',)
    assert IdData(np.zeros(5), np.zeros(5), 1.0).input_names == ('u1',)
    assert np.allclose(d.time[:3], [0, 0.5, 1.0])
    assert IdData(np.zeros(5), np.zeros((5, 0)), 1.0).nu == 0


@pytest.mark.parametrize(
    ('kwargs', 'match'),
    [
        ({'y': [1.0, np.nan], 'u': [0.0, 0.0], 'Ts': 1.0}, 'y contains 1 NaN'),
        ({'y': [1.0, 2.0], 'u': [0.0, np.inf], 'Ts': 1.0}, 'u contains 1 NaN or infinite'),
        ({'y': [1.0, 2.0], 'u': [0.0], 'Ts': 1.0}, 'u has 1 samples but y has 2'),
        ({'y': [1.0, 2.0], 'u': [0.0, 1.0], 'Ts': 0.0}, 'Ts must be a positive'),
        ({'y': [1.0, 2.0], 'u': [0.0, 1.0], 'Ts': -1e-3}, 'Ts must be a positive'),
        ({'y': np.zeros((2, 2, 2)), 'u': [0.0, 1.0], 'Ts': 1.0}, 'y must be 1-D or 2-D'),
    ],
)
def test_constructor_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        IdData(**kwargs)


def test_names_must_match_channels():
    with pytest.raises(ValueError, match='output_names has 1 entries, expected 2'):
        IdData(np.zeros((3, 2)), np.zeros(3), 1.0, ['a'])


def test_slicing_and_split():
    d = IdData(np.arange(10.0), np.arange(10.0), 0.1)
    assert d[2:5].N == 3 and d[2:5].y[0, 0] == 2.0
    assert d[::2].Ts == pytest.approx(0.2)
    est, val = d.split(0.5)
    assert (est.N, val.N, val.y[0, 0]) == (5, 5, 5.0)
    est, val = d.split(7)
    assert (est.N, val.N) == (7, 3)
    with pytest.raises(ValueError, match='split fraction must be in'):
        d.split(1.5)
    with pytest.raises(ValueError, match='split index must be in 1..9'):
        d.split(10)
    with pytest.raises(TypeError, match='IdData index must be a slice'):
        d[3]


def test_detrend_constant_and_linear():
    t = np.arange(100.0)
    d = IdData(3 + 0.5 * t, 2 - t, 1.0)
    assert np.allclose(d.detrend().y.mean(), 0) and np.allclose(d.detrend().u.mean(), 0)
    assert np.allclose(d.detrend('linear').y, 0, atol=1e-10)
    with pytest.raises(ValueError, match='detrend kind must be'):
        d.detrend('quadratic')


def test_lowpass_bandpass_and_zero_phase_filtering():
    d = sine_data([5.0, 200.0])
    low = d.filter((0.0, 30.0), zero_phase=True)
    ref = sine_data([5.0])
    mid = slice(500, 3500)
    assert np.allclose(low.y[mid], ref.y[mid], atol=0.02)  # no phase lag
    band = d.filter((100.0, 300.0), zero_phase=True)
    assert np.allclose(band.y[mid], sine_data([200.0]).y[mid], atol=0.05)
    causal = d.filter((0.0, 30.0))
    assert np.max(np.abs(causal.y[mid] - ref.y[mid])) > 0.05  # causal filter lags
    assert d.filter((0.0, 1e9)) is d
    with pytest.raises(ValueError, match='filter band must satisfy'):
        d.filter((50.0, 10.0))
    with pytest.raises(ValueError, match='above Nyquist'):
        d.filter((600.0, np.inf))


def test_decimate():
    d = sine_data([5.0], N=4000)
    dec = d.decimate(4)
    assert dec.N == 1000 and dec.Ts == pytest.approx(4e-3)
    assert np.allclose(dec.y[100:900, 0], d.y[400:3600:4, 0], atol=0.02)
    with pytest.raises(ValueError, match='decimation factor q must be >= 1'):
        d.decimate(0)


def test_select_and_merge():
    d = IdData(np.zeros((5, 2)), np.zeros((5, 2)), 1.0)
    assert d.select([1], [0]).output_names == ('y2',)
    with pytest.raises(ValueError, match='outputs indices'):
        d.select([3])
    other = IdData(np.zeros((7, 2)), np.zeros((7, 2)), 1.0)
    assert len(merge(d, other)) == 2
    with pytest.raises(ValueError, match='experiment 1 has Ts=2.0'):
        merge(d, IdData(np.zeros((7, 2)), np.zeros((7, 2)), 2.0))
    with pytest.raises(ValueError, match='experiment 1 has ny=1'):
        merge(d, IdData(np.zeros(7), np.zeros((7, 2)), 1.0))
