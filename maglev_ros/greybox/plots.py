"""Headless PNG plots of a calibration: measured field against the nominal and calibrated models.

Built with :class:`matplotlib.figure.Figure` and the Agg canvas (no display,
no global ``pyplot`` state).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .static import StaticCalibration

__all__ = ['calibration_plot']

_AXES = ('x', 'y', 'z')


def calibration_plot(
    cal: StaticCalibration,
    index: int,
    path: str | Path,
    Ts: float = 2e-4,
    window: int = 1000,
) -> Path:
    """Plot one experiment's validation data against the nominal and the calibrated model.

    One panel per sensor axis (rows: sensors, columns: x, y, z), the field in
    mT over the first ``window`` validation samples; each panel's legend gives
    the RMS error of both models over the whole validation part.

    Parameters
    ----------
    cal : StaticCalibration
        The result (holds the validation predictions).
    index : int
        Which experiment.
    path : str or Path
        PNG file.
    Ts : float
        Sample time, s (time axis).
    window : int
        Samples shown.

    Returns
    -------
    Path
        The file written.
    """
    measured = cal.predictions[(index, 'measured')]
    nominal = cal.predictions[(index, 'nominal')]
    calibrated = cal.predictions[(index, 'calibrated')]
    fit_nom = cal.validation_nominal[index]
    fit_cal = cal.validation_calibrated[index]
    n = min(window, measured.shape[0])
    t = np.arange(n) * Ts
    exp_sensors = cal.sensors[index]
    sensors = measured.shape[1] // 3
    fig = Figure(figsize=(13, 2.6 * sensors + 1.0))
    axes = fig.subplots(sensors, 3, sharex=True, squeeze=False)
    for k in range(sensors):
        for a in range(3):
            ch = 3 * k + a
            ax = axes[k, a]
            ax.plot(t, 1e3 * measured[:n, ch], color='0.55', lw=0.8, label='measured')
            ax.plot(
                t,
                1e3 * nominal[:n, ch],
                color='tab:red',
                lw=1.2,
                label=f'nominal (rms {1e3 * fit_nom.rms[ch]:.3g} mT)',
            )
            ax.plot(
                t,
                1e3 * calibrated[:n, ch],
                color='tab:blue',
                lw=1.2,
                ls='--',
                label=f'calibrated (rms {1e3 * fit_cal.rms[ch]:.3g} mT)',
            )
            ax.set_title(f'sensor {exp_sensors[k]}  B{_AXES[a]}', fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=7, loc='upper right')
            if a == 0:
                ax.set_ylabel('field (mT)')
            if k == sensors - 1:
                ax.set_xlabel('time (s)')
    what = 'one-step Kalman prediction' if getattr(cal, 'form', None) else 'model'
    fig.suptitle(
        f'{fit_cal.experiment}: validation data, measured vs {what} - RMS error '
        f'nominal {1e3 * fit_nom.total_rms:.3g} mT, calibrated {1e3 * fit_cal.total_rms:.3g} mT '
        f'(noise {1e3 * float(np.sqrt(np.mean(cal.noise[index] ** 2))):.3g} mT)',
        fontsize=11,
    )
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=100)
    return path
