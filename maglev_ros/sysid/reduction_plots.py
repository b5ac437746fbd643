"""PNG plot of a balanced truncation: Hankel singular values and Bode of full vs reduced."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .plots import _save
from .reduction import Reduction

__all__ = ['reduction_figure', 'reduction_plot']


def reduction_figure(reduction: Reduction, n_points: int = 300) -> Figure:
    """Hankel singular values (kept / discarded) and the Bode of the first channel.

    Parameters
    ----------
    reduction : Reduction
        Result of :func:`~maglev_ros.sysid.reduction.balanced_truncation`.
    n_points : int
        Frequencies, log-spaced up to Nyquist.

    Returns
    -------
    Figure
        Three axes: singular values, magnitude, phase.
    """
    full, reduced = reduction.full, reduction.reduced
    fig = Figure(figsize=(11.0, 4.0), layout='constrained')
    hsv_ax, mag_ax, phase_ax = fig.subplots(1, 3)
    index = np.arange(1, len(reduction.hsv) + 1)
    kept = index <= reduction.kept
    hsv_ax.semilogy(index[kept], reduction.hsv[kept], 'o', color='C0', label='kept')
    hsv_ax.semilogy(index[~kept], reduction.hsv[~kept], 'x', color='C3', label='discarded')
    hsv_ax.set_xlabel('state of the stable part (balanced)')
    hsv_ax.set_ylabel('Hankel singular value')
    hsv_ax.set_xticks(index)
    hsv_ax.grid(True, which='both', lw=0.3)
    hsv_ax.legend(fontsize='small')
    hsv_ax.set_title(
        f'{100 * reduction.fraction:.2f} % of the sum kept'
        + (f'; {reduction.n_unstable} unstable states kept' if reduction.n_unstable else ''),
        fontsize='medium',
    )
    nyq = 0.5 / full.Ts
    f = np.logspace(np.log10(nyq) - 3, np.log10(nyq), n_points)
    for model, label, style in (
        (full, f'full, order {full.order}', dict(color='black', lw=1.6)),
        (reduced, f'reduced, order {reduced.order}', dict(color='C1', lw=1.2, ls='--')),
    ):
        h = model.freqresp(f)[:, 0, 0]
        mag_ax.semilogx(f, 20 * np.log10(np.abs(h)), label=label, **style)
        phase_ax.semilogx(f, np.degrees(np.unwrap(np.angle(h))), **style)
    name = f'{full.input_names[0]} -> {full.output_names[0]}' if full.input_names else ''
    mag_ax.set_title(f'magnitude {name}', fontsize='medium')
    phase_ax.set_title(f'phase {name}', fontsize='medium')
    mag_ax.set_ylabel('magnitude [dB]')
    phase_ax.set_ylabel('phase [deg]')
    for ax in (mag_ax, phase_ax):
        ax.set_xlabel('frequency [Hz]')
        ax.set_xlim(f[0], f[-1])
        ax.grid(True, which='both', lw=0.3)
    mag_ax.legend(fontsize='small')
    fig.suptitle(reduction.summary(), fontsize='small')
    return fig


def reduction_plot(reduction: Reduction, path: str | Path) -> Path:
    """Write :func:`reduction_figure` to a PNG file and return its path.

    Parameters
    ----------
    reduction : Reduction
        Result of :func:`~maglev_ros.sysid.reduction.balanced_truncation`.
    path : str or Path
        PNG file to write (its directory is created).
    """
    return _save(reduction_figure(reduction), path)
