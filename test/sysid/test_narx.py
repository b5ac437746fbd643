"""Polynomial NARX with FROLS: known systems, MIMO, several experiments, sysidentpy."""

import numpy as np
import pytest

from maglev_ros.sysid import IdData, compare
from maglev_ros.sysid.narx import NarxStructure, narx

NOISE = 0.02


def siso_system(N, seed, noise=NOISE):
    """y(t) = 0.2 y(t-1) + 0.1 y(t-1) u(t-1) + 0.9 u(t-2) - 0.3 u(t-1)^2 + e(t)."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, N)
    e = noise * rng.standard_normal(N)
    y = np.zeros(N)
    for t in range(2, N):
        y[t] = 0.2 * y[t - 1] + 0.1 * y[t - 1] * u[t - 1] + 0.9 * u[t - 2]
        y[t] += -0.3 * u[t - 1] ** 2 + e[t]
    return IdData(y, u, 1.0)


SISO_TRUTH = {'y1(t-1)': 0.2, 'y1(t-1)*u1(t-1)': 0.1, 'u1(t-2)': 0.9, 'u1(t-1)^2': -0.3}


def mimo_system(N, seed, noise=NOISE):
    """Two coupled outputs, two inputs; y2 enters y1 through a product term."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, (N, 2))
    y = np.zeros((N, 2))
    e = noise * rng.standard_normal((N, 2))
    for t in range(1, N):
        y[t, 0] = 0.5 * y[t - 1, 0] + 0.8 * u[t - 1, 0] + 0.3 * y[t - 1, 1] * u[t - 1, 0]
        y[t, 1] = 0.6 * y[t - 1, 1] - 0.4 * u[t - 1, 1] + 0.2 * u[t - 1, 0] ** 2 - 0.1
        y[t] += e[t]
    return IdData(y, u, 1.0)


MIMO_TRUTH = (
    {'y1(t-1)': 0.5, 'u1(t-1)': 0.8, 'y2(t-1)*u1(t-1)': 0.3},
    {'y2(t-1)': 0.6, 'u2(t-1)': -0.4, 'u1(t-1)^2': 0.2, '1': -0.1},
)


def selected(model, output=0):
    return dict(zip(model.term_names(output), model.theta[output], strict=True))


def test_structure_counts_candidates_and_names_them():
    s = NarxStructure(ny=1, nu=1, na=2, nb=2, nk=1, degree=2)
    assert len(s.variables) == 4 and len(s.monomials) == 1 + 4 + 10
    names = [s.term_name(k, ['y'], ['u']) for k in range(len(s.monomials))]
    assert names[0] == '1' and 'y(t-1)*u(t-2)' in names and 'u(t-1)^2' in names
    assert s.max_lag == 2
    with pytest.raises(ValueError, match='degree must be >= 1'):
        NarxStructure(ny=1, nu=1, na=1, nb=1, nk=1, degree=0)


def test_siso_selects_the_true_terms_within_three_sigma():
    model = narx(siso_system(4000, seed=0), na=2, nb=2, nk=1, degree=2)
    terms = selected(model)
    assert set(terms) == set(SISO_TRUTH), model
    std = dict(zip(model.term_names(0), model.std[0], strict=True))
    for name, true in SISO_TRUTH.items():
        assert abs(terms[name] - true) < 3 * std[name], (name, terms[name], std[name])
    assert 'u1(t-2)' in str(model) and 'ERR' in str(model)


def test_mimo_one_selection_per_output():
    model = narx(mimo_system(4000, seed=2), na=1, nb=1, nk=1, degree=2)
    for i, truth in enumerate(MIMO_TRUTH):
        terms = selected(model, i)
        assert set(terms) == set(truth), model
        std = dict(zip(model.term_names(i), model.std[i], strict=True))
        for name, true in truth.items():
            assert abs(terms[name] - true) < 3 * std[name], (i, name)


def test_simulation_and_prediction_on_fresh_data():
    model = narx(siso_system(3000, seed=3), na=2, nb=2, nk=1, degree=2)
    fresh = siso_system(2000, seed=4)
    sim = compare(model, fresh)
    noise_free = siso_system(2000, seed=4, noise=0.0)
    assert np.max(np.abs(model.simulate(fresh) - noise_free.y)[10:]) < 0.1
    assert sim.fit[0] > 90
    one = model.predict(fresh, 1)
    np.testing.assert_allclose(fresh.y - one, model.residuals(fresh))
    # a long horizon forgets the measured outputs: it tends to the simulation
    long = model.predict(fresh, 60)
    np.testing.assert_allclose(long[200:], model.simulate(fresh)[200:], atol=1e-6)


def test_experiments_are_not_joined():
    """Noise-free experiments: stacked per experiment the fit is exact, joined it is not."""
    a = siso_system(1500, seed=5, noise=0.0)
    b = siso_system(1500, seed=6, noise=0.0)
    both = narx([a, b], na=2, nb=2, nk=1, degree=2, n_terms=4)
    assert set(selected(both)) == set(SISO_TRUTH)
    for name, value in selected(both).items():
        assert value == pytest.approx(SISO_TRUTH[name], abs=1e-9)
    joined = narx(IdData(np.r_[a.y, b.y], np.r_[a.u, b.u], 1.0), 2, 2, 1, 2, n_terms=4)
    errors = [abs(v - SISO_TRUTH.get(k, 0.0)) for k, v in selected(joined).items()]
    assert max(errors) > 1e-6  # the rows straddling the boundary bias the joined fit
    with pytest.raises(ValueError, match='more than 3 samples'):
        narx([a, a[:3]], na=2, nb=2, nk=1)


def test_agrees_with_sysidentpy():
    """Same data, same candidates, same criterion: the same terms and parameters."""
    pytest.importorskip('sysidentpy')
    from sysidentpy.basis_function import Polynomial
    from sysidentpy.model_structure_selection import FROLS

    data = siso_system(3000, seed=8)
    ours = narx(data, na=2, nb=2, nk=1, degree=2, n_terms=4)
    from sysidentpy.parameter_estimation import LeastSquares

    theirs = FROLS(
        order_selection=False,
        n_terms=4,
        ylag=2,
        xlag=2,
        basis_function=Polynomial(degree=2),
        estimator=LeastSquares(),
    )
    theirs.fit(X=data.u, y=data.y)

    # sysidentpy codes y(k-l) as 1000 + l and x1(k-l) as 2000 + l
    def code(name):
        base = 1000 if name.startswith('y') else 2000
        return base + int(name.split('t-')[1].rstrip(')').split(')')[0])

    ours_terms = {}
    for name, value in selected(ours).items():
        key = tuple(
            sorted(
                code(p.split('^')[0])
                for p in name.split('*')
                for _ in range(int(p.split('^')[1]) if '^' in p else 1)
            )
        )
        ours_terms[key] = value
    theirs_terms = {
        tuple(sorted(int(c) for c in row if c)): float(v)
        for row, v in zip(theirs.final_model, theirs.theta.ravel(), strict=True)
    }
    assert set(ours_terms) == set(theirs_terms)
    for key, value in ours_terms.items():
        assert value == pytest.approx(theirs_terms[key], abs=1e-3)
