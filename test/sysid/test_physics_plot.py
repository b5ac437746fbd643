"""The physics check's Bode plot: read in the compared band, the left-out strip named."""

import numpy as np
import pytest

from maglev_ros.physics import linearize, make_model
from maglev_ros.sysid import PolyModel, make_orders
from maglev_ros.sysid.physics_check import compare_response, local_plant
from maglev_ros.sysid.physics_plot import physics_check_figure

TS = 2e-4
BAND = (10.0, 300.0)


@pytest.fixture(scope='module')
def plant():
    return local_plant(linearize(make_model('maggy_v2')).reduced(), TS, 'Bx_0', 'x', 1)


def _lowpass(gain, pole, far_pole):
    """A first-order model with a second pole far above the band (a large phase there)."""
    a = np.convolve([1.0, -pole], [1.0, -far_pole])
    b = np.array([0.0, gain * (1 - pole) * (1 - far_pole)])
    theta = np.r_[a[1:], b[1:]]
    return PolyModel('arx', make_orders(1, 1, na=2, nb=1, nk=1), theta, TS, np.eye(1))


def test_axes_fit_the_compared_band_and_the_strip_is_explained(plant):
    models = [_lowpass(2e-3, 0.9, -0.9), _lowpass(2.1e-3, 0.9, -0.95)]
    checks = [compare_response(m, plant, BAND) for m in models]
    fig = physics_check_figure(models, ['ARX 2 1 1', 'ARX'], plant, BAND, checks)
    mag, phase = fig.axes
    low, high = mag.get_xlim()
    assert BAND[0] / 1.3 < low < BAND[0] and BAND[1] < high < BAND[1] * 1.3
    # scaled to the band: a few tens of dB and degrees, not the -1000 deg above it
    assert np.diff(mag.get_ylim())[0] < 40 and np.diff(phase.get_ylim())[0] < 200
    texts = [t.get_text() for t in mag.get_legend().get_texts()]
    assert any(t.startswith('left out: 14.') and 'resonance' in t for t in texts), texts
    assert texts[1].startswith('ARX (na=2  nb=1  nk=1): max ')  # orders of a label without them
    assert 'physics check: Bx_0' in mag.get_title()


def test_full_range_on_request(plant):
    model = _lowpass(2e-3, 0.9, -0.9)
    fig = physics_check_figure([model], ['ARX 2 1 1'], plant, BAND, full_range=True)
    low, high = fig.axes[0].get_xlim()
    assert low == 1.0 and high == pytest.approx(0.5 / TS)
