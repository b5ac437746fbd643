"""The checks behind "calibrated": each failure named, the status and exit status it gives."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from maglev_ros.greybox import assess, parameter_vector
from maglev_ros.greybox.identifiability import Identifiability
from maglev_ros.greybox.static import ValidationFit
from maglev_ros.physics import load_parameters

FREE = ('magnet.mass', 'magnet.polarization')


def result(**changes):
    vector = parameter_vector(load_parameters('maggy_v2')).with_free(FREE)
    nominal = {n: vector[n].nominal for n in FREE}
    base = SimpleNamespace(
        vector=vector,
        names=FREE,
        estimate={n: 1.01 * v for n, v in nominal.items()},
        correlated=(('magnet.mass', 'magnet.polarization', 0.95),),
        identifiability=Identifiability(FREE, 2, (), np.ones(2)),
        validation_nominal=(ValidationFit('run', np.array([90.0]), np.array([2e-4])),),
        validation_calibrated=(ValidationFit('run', np.array([95.0]), np.array([1e-4])),),
        delays=(1,),
        delay_costs=((0.8, 0.7, 0.9),),
        notes=(),
    )
    return SimpleNamespace(**{**vars(base), **changes})


def test_a_clean_result_is_calibrated():
    verdict = assess(result())
    assert verdict.status == 'calibrated' and verdict.warnings == () and verdict.exit_status == 0


def test_a_parameter_at_its_bound():
    cal = result()
    upper = cal.vector['magnet.polarization'].upper
    verdict = assess(result(estimate={**cal.estimate, 'magnet.polarization': upper}))
    assert verdict.status == 'partly calibrated' and verdict.exit_status == 1
    assert 'magnet.polarization = ' in verdict.warnings[0] and 'upper bound' in verdict.warnings[0]
    lower = {n: cal.vector[n].lower for n in FREE}
    assert assess(result(estimate=lower)).status == 'not calibrated'  # every one at a bound


def test_worse_validation_undetermined_delay_and_correlation():
    worse = (ValidationFit('run', np.array([80.0]), np.array([3e-4])),)
    verdict = assess(result(validation_calibrated=worse))
    assert verdict.status == 'not calibrated'
    assert 'predicts the validation data worse than the nominal one' in verdict.warnings[0]
    verdict = assess(result(delay_costs=((0.8, 0.8, 0.8),)))
    assert verdict.status == 'partly calibrated'
    assert (
        'sensor delay is not determined' in verdict.warnings[0]
        and '--delay' in verdict.warnings[0]
    )
    verdict = assess(result(correlated=(('magnet.mass', 'magnet.polarization', 0.9995),)))
    assert verdict.status == 'partly calibrated' and 'r = +0.9995' in verdict.warnings[0]
    assert assess(result(notes=('the fit stopped',))).warnings == ('the fit stopped',)
