"""The physics check as a Bode plot: identified models over the linearisation's response.

One figure per SISO path (e.g. ``Bx_0`` against ``u_x``): magnitude (dB of
mT/A) and phase (degrees) of each identified model and of the true local
transfer function (:func:`~.physics_check.local_plant`, black), from 1 Hz to
Nyquist. The band the check compares is left white, the rest shaded; the
neighbourhood of an undamped resonance the check leaves out is hatched. The
legend gives each model's deviation (max over the band).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from .physics_check import RESONANCE_WIDTH, FrequencyDeviation, LocalPlant

__all__ = ['physics_check_figure', 'physics_check_plot']

_MT = 1e3  # T -> mT


def _siso(response: np.ndarray) -> np.ndarray:
    response = np.asarray(response)
    return response[:, 0, 0] if response.ndim == 3 else response


def physics_check_figure(
    models: Sequence[object],
    labels: Sequence[str],
    plant: LocalPlant,
    band: tuple[float, float],
    deviations: Sequence[FrequencyDeviation | str | None] = (),
    n_points: int = 500,
) -> Figure:
    """Bode plot of identified SISO models against the linearisation.

    Parameters
    ----------
    models : sequence of PolyModel
        SISO models (output in T, input in A), same ``Ts`` as ``plant``.
    labels : sequence of str
        Legend names.
    plant : LocalPlant
        The true local transfer function.
    band : (float, float)
        The compared band, Hz (unshaded).
    deviations : sequence of FrequencyDeviation, str or None, optional
        Each model's check, shown in the legend.
    n_points : int
        Log-spaced frequencies from 1 Hz to Nyquist.

    Returns
    -------
    Figure
        Magnitude (top) and phase (bottom) axes.
    """
    nyquist = 0.5 / plant.Ts
    f = np.geomspace(1.0, nyquist, int(n_points))
    fig = Figure(figsize=(8.0, 6.5), layout='constrained')
    mag_ax, phase_ax = fig.subplots(2, 1, sharex=True)
    truth = plant.freqresp(f)
    truth_phase = np.degrees(np.unwrap(np.angle(truth)))
    inside = (f >= band[0]) & (f <= band[1])
    mid = np.flatnonzero(inside)[len(np.flatnonzero(inside)) // 2] if inside.any() else 0
    for k, (model, label) in enumerate(zip(models, labels, strict=True)):
        h = _siso(model.freqresp(f))
        phase = np.degrees(np.unwrap(np.angle(h)))
        phase -= 360.0 * np.round((phase[mid] - truth_phase[mid]) / 360.0)  # same branch
        check = deviations[k] if k < len(deviations) else None
        if isinstance(check, FrequencyDeviation):
            label = f'{label}: max {check.max_db:.2f} dB / {check.max_deg:.1f} deg'
        mag_ax.semilogx(f, 20 * np.log10(np.abs(h) * _MT), color=f'C{k}', lw=1.2, label=label)
        phase_ax.semilogx(f, phase, color=f'C{k}', lw=1.2)
    mag_ax.semilogx(f, 20 * np.log10(np.abs(truth) * _MT), 'k', lw=2.2, alpha=0.6,
                    label='linearisation (the physics)')  # fmt: skip
    phase_ax.semilogx(f, truth_phase, 'k', lw=2.2, alpha=0.6)
    for ax in (mag_ax, phase_ax):
        ax.axvspan(f[0], band[0], color='0.85', lw=0)
        ax.axvspan(band[1], f[-1], color='0.85', lw=0)
        for fr in plant.resonances():
            if band[0] <= fr <= band[1]:
                ax.axvspan(fr - RESONANCE_WIDTH, fr + RESONANCE_WIDTH, fill=False,
                           hatch='///', edgecolor='0.6', lw=0)  # fmt: skip
        ax.grid(True, which='both', lw=0.3)
        ax.set_xlim(f[0], f[-1])
    mag_ax.set_ylabel('magnitude [dB mT/A]')
    phase_ax.set_ylabel('phase [deg]')
    phase_ax.set_xlabel('frequency [Hz] (shaded: outside the compared band)')
    mag_ax.set_title(
        f'{plant.output} against the {_pair_name(plant)}: identified models and the '
        f'linearisation, compared over {band[0]:g}-{band[1]:g} Hz',
        fontsize='medium',
    )
    mag_ax.legend(fontsize='small', loc='lower left')
    return fig


def _pair_name(plant: LocalPlant) -> str:
    w = np.asarray(plant.weights)
    if w.size == 4 and w[0] and w[1] == -w[0] and not w[2:].any():
        return 'x pair input'
    if w.size == 4 and w[2] and w[3] == -w[2] and not w[:2].any():
        return 'y pair input'
    return 'input'


def physics_check_plot(
    models: Sequence[object],
    path: str | Path,
    labels: Sequence[str],
    plant: LocalPlant,
    band: tuple[float, float],
    deviations: Sequence[FrequencyDeviation | str | None] = (),
) -> Path:
    """Write :func:`physics_check_figure` to a PNG file.

    Parameters
    ----------
    models, labels, plant, band, deviations
        As :func:`physics_check_figure`.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = physics_check_figure(models, labels, plant, band, deviations)
    fig.savefig(path, dpi=110)
    return path
