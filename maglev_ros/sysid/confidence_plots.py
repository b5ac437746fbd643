"""PNG plots with confidence bands: Bode, step response and simulated output.

The band is ``value +- sigma std`` from :mod:`maglev_ros.sysid.confidence`
(default 3 standard deviations), shaded in the model's colour; the title says
how many standard deviations are shown.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .confidence import DEFAULT_SIGMA, frequency_band, simulation_band, step_band
from .dataset import IdData
from .model import PolyModel
from .plots import _save, display_scale

__all__ = ['bode_band_figure', 'bode_band_plot', 'output_band_figure', 'step_band_figure']


def bode_band_figure(
    models: Sequence[PolyModel],
    labels: Sequence[str] | None = None,
    sigma: float = DEFAULT_SIGMA,
    n_points: int = 200,
) -> Figure:
    """Bode plot (dB, degrees) of every channel with each model's band.

    Parameters
    ----------
    models : sequence of PolyModel
        Models with parameter covariances, equal ``ny``, ``nu``, ``Ts``.
    labels : sequence of str, optional
        Legend names.
    sigma : float
        Standard deviations of the band.
    n_points : int
        Frequencies, log-spaced up to Nyquist.

    Returns
    -------
    Figure
        Magnitude and phase rows per output, one column per input.
    """
    labels = list(labels) if labels else [m.structure for m in models]
    first = models[0]
    nyq = 0.5 / first.Ts
    f = np.logspace(np.log10(nyq) - 3, np.log10(nyq), n_points)
    fig = Figure(figsize=(max(7.0, 5 * first.nu), 5.0 * first.ny), layout='constrained')
    axes = fig.subplots(2 * first.ny, first.nu, squeeze=False)
    for k, (model, label) in enumerate(zip(models, labels, strict=True)):
        mag, phase = frequency_band(model, f, sigma)
        for i in range(first.ny):
            scale, _ = display_scale(first.output_units[i] if first.output_units else '')
            shift = 20 * np.log10(scale)
            for j in range(first.nu):
                if not model.orders.nb[i, j]:
                    continue
                for ax, band, add in (
                    (axes[2 * i, j], mag, shift),
                    (axes[2 * i + 1, j], phase, 0),
                ):
                    ax.fill_between(
                        f, band.lower[:, i, j] + add, band.upper[:, i, j] + add,
                        color=f'C{k}', alpha=0.25, lw=0,
                    )  # fmt: skip
                    ax.semilogx(
                        f, band.value[:, i, j] + add, color=f'C{k}',
                        label=f'{label} (+-{sigma:g} sd)' if ax is axes[0, 0] else None,
                    )  # fmt: skip
    for ax in axes[0::2].ravel():  # a band can reach -inf dB where |G| is uncertain
        values = np.concatenate([line.get_ydata() for line in ax.get_lines()] or [[0.0]])
        finite = values[np.isfinite(values)]
        if finite.size:
            ax.set_ylim(finite.min() - 20.0, finite.max() + 20.0)
    for i in range(first.ny):
        for j in range(first.nu):
            axes[2 * i, j].set_title(
                f'{first.input_names[j]} -> {first.output_names[i]}', fontsize='medium'
            )
            axes[2 * i, j].set_ylabel('magnitude [dB]')
            axes[2 * i + 1, j].set_ylabel('phase [deg]')
            axes[2 * i + 1, j].set_xlabel('frequency [Hz]')
            for ax in (axes[2 * i, j], axes[2 * i + 1, j]):
                ax.set_xlim(f[0], f[-1])
                ax.grid(True, which='both', lw=0.3)
    axes[0, 0].legend(fontsize='small')
    fig.suptitle(f'Bode with {sigma:g}-standard-deviation confidence bands', fontsize='medium')
    return fig


def bode_band_plot(
    models: Sequence[PolyModel],
    path: str | Path,
    labels: Sequence[str] | None = None,
    sigma: float = DEFAULT_SIGMA,
) -> Path:
    """Write :func:`bode_band_figure` to a PNG file and return its path.

    Parameters
    ----------
    models : sequence of PolyModel
        Models with parameter covariances.
    path : str or Path
        PNG file to write (its directory is created).
    labels : sequence of str, optional
        Legend names.
    sigma : float
        Standard deviations of the band.
    """
    return _save(bode_band_figure(models, labels, sigma), path)


def step_band_figure(
    models: Sequence[PolyModel],
    n_samples: int,
    labels: Sequence[str] | None = None,
    sigma: float = DEFAULT_SIGMA,
) -> Figure:
    """Unit-step responses of every channel with each model's band.

    Parameters
    ----------
    models : sequence of PolyModel
        Models with parameter covariances.
    n_samples : int
        Samples of the responses.
    labels : sequence of str, optional
        Legend names.
    sigma : float
        Standard deviations of the band.
    """
    labels = list(labels) if labels else [m.structure for m in models]
    first = models[0]
    t = np.arange(n_samples) * first.Ts
    fig = Figure(figsize=(max(7.0, 4.5 * first.nu), 3.2 * first.ny), layout='constrained')
    axes = fig.subplots(first.ny, first.nu, squeeze=False)
    for k, (model, label) in enumerate(zip(models, labels, strict=True)):
        band = step_band(model, n_samples, sigma)
        for i in range(first.ny):
            for j in range(first.nu):
                ax = axes[i, j]
                ax.fill_between(
                    t, band.lower[:, i, j], band.upper[:, i, j], color=f'C{k}', alpha=0.25, lw=0,
                    step='post',
                )  # fmt: skip
                ax.step(t, band.value[:, i, j], where='post', color=f'C{k}',
                        label=f'{label} (+-{sigma:g} sd)')  # fmt: skip
    for i in range(first.ny):
        for j in range(first.nu):
            ax = axes[i, j]
            ax.set_title(f'{first.input_names[j]} -> {first.output_names[i]}', fontsize='medium')
            ax.set_xlabel('time [s]')
            ax.set_ylabel(f'{first.output_names[i]} per unit {first.input_names[j]}')
            ax.grid(True, lw=0.3)
    axes[0, 0].legend(fontsize='small')
    fig.suptitle(f'Step responses with {sigma:g}-standard-deviation bands', fontsize='medium')
    return fig


def output_band_figure(
    model: PolyModel,
    data: IdData,
    label: str = 'model',
    sigma: float = DEFAULT_SIGMA,
    n_samples: int = 400,
) -> Figure:
    """Measured output and the model's simulated output with its band (first samples).

    Parameters
    ----------
    model : PolyModel
        Model with a parameter covariance.
    data : IdData
        Validation data (its first ``n_samples`` are drawn, zero initial state).
    label : str
        Legend name.
    sigma : float
        Standard deviations of the band.
    n_samples : int
        Samples drawn.
    """
    part = data[: min(n_samples, data.N)]
    band = simulation_band(model, part, sigma)
    t = part.time
    fig = Figure(figsize=(9.0, 2.8 * model.ny), layout='constrained')
    axes = fig.subplots(model.ny, 1, squeeze=False)[:, 0]
    for i, ax in enumerate(axes):
        scale, unit = display_scale(model.output_units[i] if model.output_units else '')
        ax.plot(t, part.y[:, i] * scale, color='black', lw=0.8, label='measured')
        ax.fill_between(t, band.lower[:, i] * scale, band.upper[:, i] * scale, color='C0',
                        alpha=0.3, lw=0)  # fmt: skip
        ax.plot(t, band.value[:, i] * scale, color='C0', lw=1.0,
                label=f'{label} simulated (+-{sigma:g} sd)')  # fmt: skip
        ax.set_ylabel(f'{model.output_names[i]} [{unit}]' if unit else model.output_names[i])
        ax.grid(True, lw=0.3)
    axes[-1].set_xlabel('time [s]')
    axes[0].legend(fontsize='small', loc='upper right')
    fig.suptitle(
        f'Simulated output with {sigma:g}-standard-deviation band (zero initial state)',
        fontsize='medium',
    )
    return fig
