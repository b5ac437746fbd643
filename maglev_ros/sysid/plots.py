"""Headless PNG plots: compare, residual correlations, Bode.

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas,
so no display and no global ``pyplot`` state are involved.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .dataset import IdData
from .model import PolyModel
from .validation import ResidualAnalysis, compare

__all__ = ['bode_plot', 'compare_plot', 'resid_plot']


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path


def compare_plot(
    data: IdData,
    models: Sequence[PolyModel],
    path: str | Path,
    labels: Sequence[str] | None = None,
    horizon: int | None = None,
    ic: str = 'zero',
) -> Path:
    """Plot measured outputs against each model's output, fit % in the legend.

    Parameters
    ----------
    data : IdData
        Validation data.
    models : sequence of PolyModel
        Models to compare.
    path : str or Path
        PNG file to write.
    labels : sequence of str, optional
        Legend names of the models (default their structure).
    horizon : int or None
        Prediction horizon (None: simulation).
    ic : {'zero', 'estimate'}
        Initial conditions.

    Returns
    -------
    Path
        The written file.
    """
    labels = list(labels) if labels else [m.structure for m in models]
    fig = Figure(figsize=(9, 2.8 * data.ny))
    axes = fig.subplots(data.ny, 1, squeeze=False)[:, 0]
    t = data.time
    for i, ax in enumerate(axes):
        ax.plot(t, data.y[:, i], color='0.3', lw=0.8, label='measured')
        for model, label in zip(models, labels, strict=True):
            result = compare(model, data, horizon, ic)
            ax.plot(t, result.yhat[:, i], lw=0.8, label=f'{label}: {result.fit[i]:.1f}%')
        unit = f' [{data.output_units[i]}]' if data.output_units[i] else ''
        ax.set_ylabel(data.output_names[i] + unit)
        ax.legend(loc='upper right', fontsize='small')
    axes[-1].set_xlabel('time [s]')
    what = 'simulation' if horizon is None else f'{horizon}-step prediction'
    fig.suptitle(f'Measured vs model output ({what})')
    fig.tight_layout()
    return _save(fig, path)


def resid_plot(
    analysis: ResidualAnalysis,
    path: str | Path,
    output_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
) -> Path:
    """Plot residual autocorrelation and input-residual cross-correlation with 99 % bounds.

    Parameters
    ----------
    analysis : ResidualAnalysis
        Result of :func:`~.validation.resid`.
    path : str or Path
        PNG file to write.
    output_names, input_names : sequence of str, optional
        Channel names for the titles.

    Returns
    -------
    Path
        The written file.
    """
    ny, nu = analysis.crosscorr.shape[:2]
    onames = list(output_names) if output_names else [f'y{i + 1}' for i in range(ny)]
    inames = list(input_names) if input_names else [f'u{j + 1}' for j in range(nu)]
    fig = Figure(figsize=(3.2 * (nu + 1), 2.6 * ny))
    axes = fig.subplots(ny, nu + 1, squeeze=False)
    lags = analysis.lags
    for i in range(ny):
        panels = [(analysis.autocorr[i], f'autocorr e({onames[i]})')]
        panels += [
            (analysis.crosscorr[i, j], f'xcorr e({onames[i]}), {inames[j]}') for j in range(nu)
        ]
        for ax, (values, title) in zip(axes[i], panels, strict=True):
            ax.vlines(lags, 0, values, lw=1.5)
            ax.axhspan(-analysis.bound, analysis.bound, color='tab:blue', alpha=0.15)
            ax.axhline(0, color='k', lw=0.5)
            ax.set_title(title, fontsize='small')
            ax.set_xlabel('lag [samples]')
    fig.suptitle(analysis.summary(), fontsize='small')
    fig.tight_layout()
    return _save(fig, path)


def bode_plot(
    models: Sequence[PolyModel],
    path: str | Path,
    labels: Sequence[str] | None = None,
    n_points: int = 400,
) -> Path:
    """Bode plot (magnitude in dB, phase in degrees) of every input-output channel.

    Parameters
    ----------
    models : sequence of PolyModel
        Models with equal ``ny``, ``nu`` and ``Ts``.
    path : str or Path
        PNG file to write.
    labels : sequence of str, optional
        Legend names.
    n_points : int
        Frequencies, log-spaced up to Nyquist.

    Returns
    -------
    Path
        The written file.
    """
    labels = list(labels) if labels else [m.structure for m in models]
    first = models[0]
    nyq = 0.5 / first.Ts
    f = np.logspace(np.log10(nyq) - 3, np.log10(nyq), n_points)
    fig = Figure(figsize=(4 * first.nu, 4.5 * first.ny))
    axes = fig.subplots(2 * first.ny, first.nu, squeeze=False)
    for model, label in zip(models, labels, strict=True):
        H = model.freqresp(f)
        for i in range(first.ny):
            for j in range(first.nu):
                mag = 20 * np.log10(np.maximum(np.abs(H[:, i, j]), 1e-300))
                axes[2 * i, j].semilogx(f, mag, label=label)
                axes[2 * i + 1, j].semilogx(f, np.degrees(np.unwrap(np.angle(H[:, i, j]))))
                axes[2 * i, j].set_title(
                    f'{first.input_names[j]} -> {first.output_names[i]}', fontsize='small'
                )
                axes[2 * i, j].set_ylabel('magnitude [dB]')
                axes[2 * i + 1, j].set_ylabel('phase [deg]')
                axes[2 * i + 1, j].set_xlabel('frequency [Hz]')
    axes[0, 0].legend(fontsize='small')
    fig.tight_layout()
    return _save(fig, path)
