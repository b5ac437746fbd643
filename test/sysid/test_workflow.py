import os

import numpy as np
import pytest

from maglev_ros.sysid import IdData
from maglev_ros.sysid.cancellation import cancelling_pairs, without_cancelling_pairs
from maglev_ros.sysid.fortran_output import captured_fd_stdout
from maglev_ros.sysid.workflow import (
    DegenerateDataError,
    ModelSpec,
    identify,
    identify_outputs,
    offset_hints,
)

from .systems import TS, lab_second_order


@pytest.fixture(scope='module')
def lab_halves():
    return lab_second_order().detrend().split(0.5)


def test_over_parameterised_iv_is_validated_without_its_cancelling_pairs(lab_halves):
    # the README's flagship IV 7 9 1 on 2nd-order data: pole 1.41, which the
    # simulation-based compare cannot use; its unstable poles cancel against zeros
    est, val = lab_halves
    result = identify(est, val, [ModelSpec('iv', {'na': 7, 'nb': 9, 'nk': 1})])
    (row,) = result.rows
    assert not row.model.is_stable
    assert row.validated.is_stable and row.validated.orders.na[0, 0] < 7
    assert 'validated without the' in row.reason and 'cancel' in row.notes[0]
    assert row.fit_validation[0] > 99.0 and row.fit_estimation[0] > 99.0
    assert row.validated.report is None and row.validated.covariance is None
    # the reduction is approximate: what it left out shows in the input independence test
    assert row.status == 'independence failed' and not row.usable and result.exit_status == 1
    assert row.residual_verdict == 'fail: independence' and 'past inputs' in row.reason
    # the right orders pass: IV has no noise model, so only independence is required
    (right,) = identify(est, val, [ModelSpec('iv', {'na': 2, 'nb': 2, 'nk': 1})]).rows
    assert right.status == 'ok' and right.usable and not right.residuals.white
    assert 'whiteness not required' in right.residuals.summary()


def test_a_wrong_noise_model_is_not_ok(lab_halves):
    # white sensor noise on the output: ARX's noise model 1/A is wrong, its residuals
    # are coloured; the status names the failed test, the k-step fit is still given
    est, val = lab_halves
    result = identify(est, val, [ModelSpec('arx', {'na': 2, 'nb': 2, 'nk': 1})])
    (row,) = result.rows
    assert row.status == 'whiteness failed' and not row.usable and result.exit_status == 1
    assert 'not white' in row.reason and 'noise model' in row.reason
    assert row.kstep == 5 and row.kstep_validation[0] > 90.0
    assert not result.closed_loop and 'no feedback' in result.feedback.summary()


def test_cancelling_pairs_of_a_constructed_model():
    # A = (1 - 0.9 q^-1)(1 - 1.3 q^-1), B = q^-1 (1 - 1.31 q^-1): the 1.3 pole cancels
    from maglev_ros.sysid import PolyModel
    from maglev_ros.sysid.orders import make_orders

    a = np.poly([0.9, 1.3])
    b = np.poly([1.31])
    model = PolyModel('arx', make_orders(1, 1, na=2, nb=2, nk=1), np.r_[a[1:], b], TS, np.eye(1))
    ((pole, zero),) = cancelling_pairs(model)
    assert pole == pytest.approx(1.3) and zero == pytest.approx(1.31)
    reduced = without_cancelling_pairs(model)
    assert reduced.orders.describe() == make_orders(1, 1, na=1, nb=1, nk=1).describe()
    assert reduced.poles() == pytest.approx([0.9]) and reduced.is_stable
    assert cancelling_pairs(model, tol=0.001) == []


def test_a_failed_model_gets_its_row_and_the_others_are_kept(lab_halves):
    # a second input that stays at zero: a model using it has singular equations
    est, val = (
        IdData(d.y, np.column_stack([d.u[:, 0], np.zeros(d.N)]), d.Ts, t0=d.t0) for d in lab_halves
    )
    specs = [
        ModelSpec('arx', {'na': 2, 'nb': [[2, 0]], 'nk': 1}),
        ModelSpec('arx', {'na': 2, 'nb': 2, 'nk': 1}),
        ModelSpec('iv', {'na': 2, 'nb': [[2, 0]], 'nk': 1}),
    ]
    result = identify(est, val, specs)
    ok, failed, iv = result.rows
    assert ok.fit_validation[0] > 99.0 and ok.model is not None
    assert iv.status == 'ok' and iv.fit_validation[0] > 99.0
    assert failed.status == 'failed' and failed.model is None
    assert 'singular equations' in failed.reason
    assert np.isnan(failed.fit_validation).all() and result.exit_status == 1
    # the constant input is named in the hints
    assert any("input 'u2' (always 0) is constant" in h for h in result.hints)


def test_constant_inputs_are_one_clear_error(lab_halves):
    est, val = (
        IdData(d.y, np.full(d.N, 0.3), d.Ts, ['Bx'], ['Ix'], ['T'], ['A']) for d in lab_halves
    )
    with pytest.raises(DegenerateDataError, match=r"input 'Ix' \(always 0.3 A\) is constant"):
        identify(est, val, [ModelSpec('arx', {'na': 2, 'nb': 2, 'nk': 1})])


def test_orders_that_cannot_be_estimated_are_refused_before_fitting(lab_halves):
    est, val = lab_halves
    specs = [ModelSpec('arx', {'na': 2, 'nb': 2}), ModelSpec('arx', {'na': 90, 'nb': 90})]
    with pytest.raises(ValueError, match='ARX 90 90 1: .* fewer samples than parameters'):
        identify(est[:150], val, specs)


def test_an_unstable_model_is_judged_on_k_step_prediction():
    # an unstable plant (pole 1.01): ARX finds it, no zero cancels it
    rng = np.random.default_rng(2)
    u = rng.standard_normal(600)
    y = np.zeros(600)
    for t in range(1, 600):
        y[t] = 1.01 * y[t - 1] + u[t - 1] + 0.1 * rng.standard_normal()
    est, val = IdData(y, u, TS).split(0.5)
    result = identify(est, val, [ModelSpec('arx', {'na': 1, 'nb': 1, 'nk': 1})])
    (row,) = result.rows
    # it predicts well and its residuals pass: usable, status "unstable"
    assert row.status == 'unstable' and row.usable and result.exit_status == 0
    assert 'largest pole 1.01' in row.reason and row.residual_verdict == 'pass'
    assert np.isnan(row.fit_validation).all() and row.prediction_fit[0] > 95.0
    assert row.kstep == 5 and row.kstep_validation[0] > 90.0 and row.kstep_estimation[0] > 90.0
    # with --horizon the main fits are k-step fits too (it used to be n/a)
    (ahead,) = identify(est, val, [ModelSpec('arx', {'na': 1, 'nb': 1, 'nk': 1})], horizon=1).rows
    assert ahead.status == 'unstable' and ahead.fit_validation[0] > 95.0 and ahead.kstep == 1


def test_output_equal_to_input_is_one_clear_error():
    data = IdData(np.arange(50.0) % 7, np.arange(50.0) % 7, TS, ['Bx'], ['Bx'])
    with pytest.raises(DegenerateDataError, match="output 'Bx' and input 'Bx' are the same"):
        identify(*data.split(0.5), [ModelSpec('arx', {'na': 1, 'nb': 1})])


def test_offset_hint_only_when_an_offset_dominates():
    raw = lab_second_order(N=2000)
    (hint,) = offset_hints(raw)
    assert hint.startswith('Bx has an offset') and '--detrend' in hint
    assert offset_hints(raw.detrend()) == ()


def test_a_silent_output_gets_a_no_response_row(lab_halves):
    est, val = lab_halves
    two = [
        IdData(np.column_stack([d.y[:, 0], np.zeros(d.N)]), d.u, d.Ts, ['Bx', 'Bz'], t0=d.t0)
        for d in (est, val)
    ]
    result = identify_outputs(*two, ModelSpec('oe', {'nb': 2, 'nf': 2, 'nk': 1}))
    bx, bz = result.rows
    assert bx.status == 'ok' and bx.outputs == ('Bx',) and bx.fit_validation[0] > 99.0
    assert bz.status == 'no response' and bz.usable and result.exit_status == 0
    still = [IdData(np.zeros((d.N, 2)), d.u, d.Ts, ['Bx', 'Bz']) for d in (est, val)]
    result = identify_outputs(*still, ModelSpec('arx', {'na': 2, 'nb': 2, 'nk': 1}))
    assert [r.status for r in result.rows] == ['failed', 'failed'] and result.exit_status == 1
    assert 'the inputs did not reach the plant' in result.rows[0].reason


def test_validation_half_keeps_the_record_time_axis(lab_halves):
    est, val = lab_halves
    assert est.time[0] == 0.0 and val.time[0] == pytest.approx(12500 * TS)
    assert val.detrend().select(outputs=[0]).time[0] == val.time[0]


def test_fortran_text_on_fd_1_is_captured(capfd):
    print('before', flush=True)
    with captured_fd_stdout() as text:
        os.write(1, b' ** On entry to DLASCL parameter number  4 had an illegal value\n')
    assert text.text.startswith('** On entry to DLASCL')
    out, _ = capfd.readouterr()
    assert out == 'before\n'


def test_failed_residual_tests_at_the_data_resolution_do_not_count():
    # quantised, otherwise noise-free field: ARX 2 2 1 explains 99.9 % or more, and its
    # residuals are the quantisation's; the tests fail, a note says so, the model is ok
    raw = lab_second_order(N=6000, noise=0.0).detrend()
    step = 2e-8  # T, far below the 1e-4 T signal
    quantised = IdData(np.round(raw.y / step) * step, raw.u, raw.Ts, ['Bx'], ['Ix'], ['T'], ['A'])
    result = identify(*quantised.split(0.5), [ModelSpec('arx', {'na': 2, 'nb': 2, 'nk': 1})])
    (row,) = result.rows
    assert row.fit_validation[0] >= 99.9 and row.residual_verdict.startswith('fail')
    assert row.status == 'ok' and row.usable and result.exit_status == 0
    assert any('resolution' in note for note in row.notes)
