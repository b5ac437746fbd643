"""The physics check as a Bode plot: identified models over the linearisation's response.

One figure per SISO path (e.g. ``Bx_0`` against ``u_x``): magnitude (dB of
mT/A) and phase (degrees) of each identified model and of the true local
transfer function (:func:`~.physics_check.local_plant`, black), over the band
the check compares (axes scaled to it; 1 Hz to Nyquist on request, the rest
shaded). The neighbourhood of an undamped resonance the check leaves out is
hatched and named in the legend, which gives each model's deviation (max over
the band).
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
    full_range: bool = False,
) -> Figure:
    """Bode plot of identified SISO models against the linearisation.

    By default the axes show the compared band (and 25 % beyond each edge),
    scaled to the curves there, so the deviations the check measures (tenths
    of a dB, degrees) can be read; ``full_range`` shows 1 Hz to Nyquist
    instead, with the band's outside shaded. The neighbourhood of an undamped
    resonance the check leaves out is hatched and named in the legend, and
    left out of the axis scaling (the linearisation's peak there is not
    compared).

    Parameters
    ----------
    models : sequence of PolyModel
        SISO models (output in T, input in A), same ``Ts`` as ``plant``.
    labels : sequence of str
        Legend names (a name without orders gets them appended).
    plant : LocalPlant
        The true local transfer function.
    band : (float, float)
        The compared band, Hz.
    deviations : sequence of FrequencyDeviation, str or None, optional
        Each model's check, shown in the legend.
    n_points : int
        Log-spaced frequencies.
    full_range : bool
        Show 1 Hz to Nyquist instead of the band.

    Returns
    -------
    Figure
        Magnitude (top) and phase (bottom) axes.
    """
    from matplotlib.patches import Patch

    from .plots import DASHES, model_title

    nyquist = 0.5 / plant.Ts
    if full_range:
        f = np.geomspace(1.0, nyquist, int(n_points))
    else:
        f = np.geomspace(max(band[0] / 1.25, 1e-3), min(band[1] * 1.25, nyquist), int(n_points))
    fig = Figure(figsize=(9.0, 6.8), layout='constrained')
    mag_ax, phase_ax = fig.subplots(2, 1, sharex=True)
    truth = plant.freqresp(f)
    truth_phase = np.degrees(np.unwrap(np.angle(truth)))
    inside = (f >= band[0]) & (f <= band[1])
    left_out = [fr for fr in plant.resonances() if band[0] <= fr <= band[1]]
    scaled = inside.copy()  # the frequencies the axes are scaled to
    for fr in left_out:
        scaled &= np.abs(f - fr) > RESONANCE_WIDTH
    mid = np.flatnonzero(inside)[len(np.flatnonzero(inside)) // 2] if inside.any() else 0
    curves = []
    for k, (model, label) in enumerate(zip(models, labels, strict=True)):
        h = _siso(model.freqresp(f))
        phase = np.degrees(np.unwrap(np.angle(h)))
        phase -= 360.0 * np.round((phase[mid] - truth_phase[mid]) / 360.0)  # same branch
        check = deviations[k] if k < len(deviations) else None
        label = model_title(model, label)
        if isinstance(check, FrequencyDeviation):
            label = f'{label}: max {check.max_db:.2f} dB / {check.max_deg:.1f} deg'
        mag = 20 * np.log10(np.abs(h) * _MT)
        style = dict(color=f'C{k}', lw=1.4, ls=DASHES[k % len(DASHES)])  # overlaps stay visible
        mag_ax.semilogx(f, mag, label=label, **style)
        phase_ax.semilogx(f, phase, **style)
        curves.append((mag, phase))
    truth_mag = 20 * np.log10(np.abs(truth) * _MT)
    mag_ax.semilogx(f, truth_mag, 'k', lw=2.2, alpha=0.6, label='linearisation (the physics)')
    phase_ax.semilogx(f, truth_phase, 'k', lw=2.2, alpha=0.6)
    curves.append((truth_mag, truth_phase))
    handles = []
    for ax in (mag_ax, phase_ax):
        if f[0] < band[0]:
            ax.axvspan(f[0], band[0], color='0.85', lw=0)
        if band[1] < f[-1]:
            ax.axvspan(band[1], f[-1], color='0.85', lw=0)
        for fr in left_out:
            ax.axvspan(fr - RESONANCE_WIDTH, fr + RESONANCE_WIDTH, fill=False,
                       hatch='///', edgecolor='0.6', lw=0)  # fmt: skip
        ax.grid(True, which='both', lw=0.3)
        ax.set_xlim(f[0], f[-1])
    if f[0] < band[0] or band[1] < f[-1]:
        handles.append(Patch(color='0.85', label='outside the compared band (not checked)'))
    for fr in left_out:
        handles.append(
            Patch(
                fill=False,
                hatch='///',
                edgecolor='0.6',
                label=f'left out: {fr:.2f} Hz ± {RESONANCE_WIDTH:g} Hz, the undamped '
                'resonance (its peak is not compared)',
            )  # fmt: skip
        )
    if not full_range and scaled.any():
        for ax, index, margin in ((mag_ax, 0, 0.5), (phase_ax, 1, 3.0)):
            low = min(float(np.min(c[index][scaled])) for c in curves)
            high = max(float(np.max(c[index][scaled])) for c in curves)
            pad = max(margin, 0.08 * (high - low))
            ax.set_ylim(low - pad, high + pad)
    mag_ax.set_ylabel('magnitude [dB mT/A]')
    phase_ax.set_ylabel('phase [deg]')
    span = '' if full_range else ' (the compared band; full range on request)'
    phase_ax.set_xlabel(f'frequency [Hz]{span}')
    mag_ax.set_title(
        f'physics check: {plant.output} against the {_pair_name(plant)}, identified models '
        f'and the linearisation, compared over {band[0]:g}-{band[1]:g} Hz',
        fontsize='medium',
    )
    lines, texts = mag_ax.get_legend_handles_labels()
    mag_ax.legend(lines + handles, texts + [h.get_label() for h in handles], fontsize='small',
                  loc='lower left')  # fmt: skip
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
    full_range: bool = False,
) -> Path:
    """Write :func:`physics_check_figure` to a PNG file.

    Parameters
    ----------
    models, labels, plant, band, deviations, full_range
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
    fig = physics_check_figure(models, labels, plant, band, deviations, full_range=full_range)
    fig.savefig(path, dpi=110)
    return path
