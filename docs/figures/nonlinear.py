# ruff: noqa: E402 - a figure script: sys.path set before the test import
"""Regenerate docs/figures/nonlinear_*.png (run from the repository root, about 1 minute).

    .venv/bin/python docs/figures/nonlinear.py

The simulated closed loops of test/sysid/physics_runs.py: NARX against ARX
(large excitation on all coils), confidence bands and balanced truncation of
the lab's ARX 7 9 1 (x pair), SINDy's eigenvalues on the true states.
"""

import sys
import warnings

warnings.simplefilter('ignore')
sys.path.insert(0, 'test')
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from sysid.physics_runs import lab_x
from sysid.test_narx_physics import height_data
from sysid.test_sindy import fit, record

from maglev_ros.physics import linearize, make_model
from maglev_ros.sysid import arx, balanced_truncation, compare_figure, narx
from maglev_ros.sysid.confidence_plots import bode_band_figure, step_band_figure
from maglev_ros.sysid.reduction_plots import reduction_figure

OUT = 'docs/figures/'


def save(fig: Figure, name: str) -> None:
    """Write ``fig`` to docs/figures/``name``."""
    FigureCanvasAgg(fig)
    fig.savefig(OUT + name, dpi=80)
    print('wrote', OUT + name)


# NARX against ARX, validation record
est, val = height_data(1), height_data(2)
linear = arx(est, 3, 3, 1)
nonlinear = narx(est, 3, 3, 1, degree=3, max_terms=40)
save(
    compare_figure(
        val, [linear, nonlinear], ['ARX 3 3 1', 'NARX 3 3 1, degree 3'], None, 'estimate'
    ),
    'nonlinear_narx_compare.png',
)

# confidence bands and reduction of the lab's ARX 7 9 1
lab_est, lab_val = lab_x(0).split(0.5)
model = arx(lab_est, 7, 9, 1)
short = arx(lab_est[:1500], 7, 9, 1)
save(bode_band_figure([model, short], ['ARX 7 9 1, 12500 samples', 'ARX 7 9 1, 1500 samples']),
     'nonlinear_bode_confidence.png')  # fmt: skip
save(step_band_figure([model, short], 100, ['12500 samples', '1500 samples']),
     'nonlinear_step_confidence.png')  # fmt: skip
save(reduction_figure(balanced_truncation(model)), 'nonlinear_reduction.png')

# SINDy on the true states: eigenvalues against the linearisation
result, _ = record('all', 0.3, 0.05, 20000, 0)
linear_model = linearize(make_model('maggy_v2'))
sindy_model = fit(result.x, result, linear_model)
A, _ = sindy_model.linearize()
found = np.linalg.eigvals(A)
truth = np.linalg.eigvals(linear_model.reduced().A)
fig = Figure(figsize=(6.0, 4.5), layout='constrained')
ax = fig.subplots()
ax.plot(
    truth.real, truth.imag, 'o', ms=11, mfc='none', color='black', label='physics linearisation'
)
ax.plot(found.real, found.imag, 'x', ms=8, color='C1', label='SINDy (true states), linearised')
ax.axvline(0.0, color='0.6', lw=0.8)
ax.set_xlabel('real part [1/s]')
ax.set_ylabel('imaginary part [1/s]')
ax.set_title('Eigenvalues at the equilibrium (10 states, yaw left out)', fontsize='medium')
ax.grid(True, lw=0.3)
ax.legend(fontsize='small')
save(fig, 'nonlinear_sindy_eigenvalues.png')
print(sindy_model.equations(2)[7])
