"""Headless PNG plots: compare, residual correlations, Bode.

Figures are built with :class:`matplotlib.figure.Figure` and the Agg canvas,
so no display and no global ``pyplot`` state are involved.

Made to be read at a glance by a control engineer:

* ``compare``: per output, one row per model over the whole validation record
  on its own time axis (the record's, not restarted at 0), a zoomed window in
  which single samples and input steps are visible, and the spectrum of each
  model's error ``y - yhat`` (RMS to three digits); legends, beside the axes,
  name every model with its fit to two decimals;
* fields given in tesla are drawn in mT; other units get engineering
  prefixes instead of an offset exponent;
* ``resid``: the model's name and the verdict in a title that fits;
* ``bode``: structurally zero paths (``nb = 0``) are labelled as such, not drawn
  as -6000 dB;
* every figure's title names what it shows and the models with their orders.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import EngFormatter

from .dataset import IdData
from .model import PolyModel
from .validation import ResidualAnalysis, compare

__all__ = [
    'DASHES',
    'ZOOM_SAMPLES',
    'bode_figure',
    'bode_plot',
    'compare_figure',
    'compare_plot',
    'display_scale',
    'model_title',
    'resid_figure',
    'resid_plot',
]

ZOOM_SAMPLES = 60  # samples in the zoomed window of compare (12 ms at 5 kHz)
MEASURED = dict(color='black', lw=1.0)
DASHES = ('-', (0, (5, 3)), (0, (1, 2)), (0, (6, 2, 1, 2)))  # solid, dashed, dotted, dash-dot


def _save(fig: Figure, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)
    return path


def display_scale(unit: str) -> tuple[float, str]:
    """Scale factor and unit to draw a channel in: tesla becomes mT.

    Parameters
    ----------
    unit : str
        The channel's unit (``'T'``, ``'A'``, ``''``, ...).

    Returns
    -------
    tuple of (float, str)
        Multiply values by the factor; the displayed unit.
    """
    return (1e3, 'mT') if unit == 'T' else (1.0, unit)


def _axis_label(ax, name: str, unit: str) -> None:
    """Label a y axis; without a unit scale, use engineering prefixes (no 1e-4 offsets)."""
    ax.set_ylabel(f'{name} [{unit}]' if unit else name)
    if unit not in ('mT', 'µT'):
        ax.yaxis.set_major_formatter(EngFormatter(unit='', places=None, sep=''))


def compare_plot(
    data: IdData,
    models: Sequence[PolyModel],
    path: str | Path,
    labels: Sequence[str] | None = None,
    horizon: int | None = None,
    ic: str = 'zero',
    zoom: int = ZOOM_SAMPLES,
) -> Path:
    """Write :func:`compare_figure` to a PNG file.

    Parameters
    ----------
    data, models, labels, horizon, ic, zoom
        As :func:`compare_figure`.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    return _save(compare_figure(data, models, labels, horizon, ic, zoom), path)


def model_title(model: PolyModel, label: str) -> str:
    """Return a model's name with its orders: the label, plus the orders if it names none.

    Parameters
    ----------
    model : PolyModel
        The model.
    label : str
        Its legend name (``'ARX 7 9 1'``, or ``'ARX'`` for order matrices).

    Returns
    -------
    str
        ``label`` if it holds a digit, else ``'label (na=[..] nb=[..] nk=[..])'``.
    """
    if any(ch.isdigit() for ch in label):
        return label
    return f'{label} ({model.orders.describe()})'


def _outside_legend(ax, **kwargs) -> None:
    """Put the legend right of the axes: it never covers the curves."""
    ax.legend(loc='upper left', bbox_to_anchor=(1.005, 1.0), borderaxespad=0.0,
              fontsize='small', framealpha=0.9, **kwargs)  # fmt: skip


def compare_figure(
    data: IdData,
    models: Sequence[PolyModel],
    labels: Sequence[str] | None = None,
    horizon: int | None = None,
    ic: str = 'zero',
    zoom: int = ZOOM_SAMPLES,
) -> Figure:
    """Plot measured outputs against each model's output, with a zoom and the error spectra.

    Per output: one row per model over the whole record (the measured output in
    grey under the model's, the zoomed window shaded; the rows share their
    scale), the zoomed window with all models (measured samples as dots), the
    inputs' steps in that window, and the amplitude spectrum of each model's
    error ``y - yhat`` (Welch; its RMS in the legend, in µT when a field's
    error is below 10 µT). Legends sit right of the axes; the title names the
    outputs, the inputs and every model with its orders.

    Parameters
    ----------
    data : IdData
        Validation data (its time axis, ``data.time``, is used as is).
    models : sequence of PolyModel
        Models to compare.
    labels : sequence of str, optional
        Legend names of the models (default their structure); a name without
        orders gets them appended in the title.
    horizon : int or None
        Prediction horizon (None: simulation).
    ic : {'zero', 'estimate'}
        Initial conditions.
    zoom : int
        Samples in the zoomed window (taken from the middle of the record).

    Returns
    -------
    Figure
        Per output the axes: one per model (whole record), zoom, inputs in the
        zoom (if any input), error spectrum. All error spectra share one scale.
    """
    from scipy.signal import welch

    labels = list(labels) if labels else [m.structure.upper() for m in models]
    results = [compare(model, data, horizon, ic) for model in models]
    t = data.time
    n_zoom = int(min(max(zoom, 10), data.N))
    z0 = (data.N - n_zoom) // 2
    zs = slice(z0, z0 + n_zoom)
    nm = len(models)
    rows = [1.5] * nm + ([3, 1.4, 2.4] if data.nu else [3, 2.4])
    panels = len(rows)
    fig = Figure(figsize=(11, 0.9 + 0.82 * sum(rows) * data.ny), layout='constrained')
    grid = fig.subplots(
        panels * data.ny, 1, squeeze=False, gridspec_kw={'height_ratios': rows * data.ny}
    )[:, 0]
    what = 'simulation' if horizon is None else f'{horizon}-step prediction'
    errors = np.stack([data.y - r.yhat for r in results])  # (models, N, ny)
    rms = np.sqrt(np.mean(errors**2, axis=1))  # (models, ny)
    field = [display_scale(u)[1] == 'mT' for u in data.output_units]
    micro = all(field) and rms.max() * 1e3 < 1e-2  # every error below 10 uT: in uT
    nseg = int(min(1024, max(16, data.N // 4)))
    error_axes = []
    for i in range(data.ny):
        scale, unit = display_scale(data.output_units[i])
        escale, eunit = (scale * 1e3, 'µT') if micro and field[i] else (scale, unit)
        name = data.output_names[i]
        axes = list(grid[panels * i : panels * (i + 1)])
        rows_full, close, error = axes[:nm], axes[nm], axes[-1]
        shown = False  # any error spectrum above zero (an exact fit has none to draw)
        y = data.y[:, i] * scale
        close.plot(t[zs], y[zs], marker='o', ms=2.5, label='measured (samples)', **MEASURED)
        for k, (result, label) in enumerate(zip(results, labels, strict=True)):
            color = f'C{k}'
            yhat = result.yhat[:, i] * scale
            fit = result.fit[i]
            text = f'{label}: {fit:.2f} %' if fit >= -999 else f'{label}: < -999 % (diverges)'
            full = rows_full[k]
            full.plot(t, y, color='0.6', lw=0.7, label='measured')
            full.plot(t, yhat, color=color, lw=0.7, label=f'{label}: fit {text.split(": ")[1]}')
            full.axvspan(t[zs][0], t[zs][-1], color='0.88', zorder=0)
            full.set_xlim(t[0], t[-1])
            _axis_label(full, name, unit)
            _outside_legend(full)
            if k:
                full.sharey(rows_full[0])
            dashes = DASHES[k % len(DASHES)]
            close.plot(t[zs], yhat[zs], color=color, lw=1.4, ls=dashes, label=text)
            freq, psd = welch(errors[k, :, i] * escale, fs=1.0 / data.Ts, nperseg=nseg)
            rms_text = f'{rms[k, i] * escale:#.3g} {eunit}'.rstrip()  # 3 digits, zeros kept
            asd_k = np.sqrt(psd[1:])
            shown |= bool(np.any(asd_k > 0))
            error.loglog(freq[1:], np.where(asd_k > 0, asd_k, np.nan), color=color, lw=1.0,
                         label=f'{label} (rms {rms_text})')  # fmt: skip
        rows_full[0].set_title(
            f"{name}: measured (grey) and each model's {what} on validation data "
            '(shaded: the zoomed window)',
            loc='left',
        )
        rows_full[-1].set_xlabel('time [s]')
        if data.nu:
            inputs = axes[-2]
            for j in range(data.nu):
                inputs.plot(t[zs], data.u[zs, j], color=f'C{7 + j % 3}', lw=1.0,
                            drawstyle='steps-post', label=data.input_names[j])  # fmt: skip
            iunit = data.input_units[0]
            inputs.set_ylabel(f'input [{iunit}]' if iunit else 'input')
            inputs.set_title('inputs in the zoomed window', loc='left')
            _outside_legend(inputs)
            inputs.set_xlabel('time [s]')
        for ax in axes[nm:-1]:  # zoom and its inputs: the same window, one sample past
            ax.set_xlim(t[z0] - 0.5 * data.Ts, t[z0 + n_zoom - 1] + 1.5 * data.Ts)
        _outside_legend(close)
        close.set_title(
            f'{name}, zoom: {n_zoom} samples ({n_zoom * data.Ts * 1e3:.3g} ms) '
            f'from t = {t[z0]:.4g} s',
            loc='left',
        )
        close.set_xlabel('time [s]')
        _axis_label(close, name, unit)
        error.set_title(
            f'{name}, error spectrum: measured - model ({what}), Welch, {nseg} samples a segment',
            loc='left',
        )
        asd = f'{eunit}/√Hz' if eunit else '1/√Hz'
        error.set_ylabel(f'error [{asd}]')
        error.set_xlabel('frequency [Hz]')
        if not shown:  # log axes cannot show zero: say so instead of an empty panel
            error.set_ylim(1e-3, 1e3)
            error.text(0.5, 0.5, 'measured - model is 0 at every sample (an exact fit)',
                       transform=error.transAxes, ha='center', va='center')  # fmt: skip
        error.set_xlim(freq[1], freq[-1])
        _outside_legend(error)
        for ax in axes:
            ax.grid(True, which='both' if ax is error else 'major', lw=0.3)
        if shown:
            error_axes.append(error)
    if error_axes:
        low = min(ax.get_ylim()[0] for ax in error_axes)
        high = max(ax.get_ylim()[1] for ax in error_axes)
        for ax in error_axes:  # one scale for every output's errors
            ax.set_ylim(low, high)
    names = ', '.join(model_title(m, lab) for m, lab in zip(models, labels, strict=True))
    head = (
        f'compare ({what}): {", ".join(data.output_names)} <- {", ".join(data.input_names)}'
        if data.nu
        else f'compare ({what}): {", ".join(data.output_names)}'
    )
    fig.suptitle(textwrap.fill(f'{head}; models {names}', width=120), fontsize='medium')
    return fig


def resid_plot(
    analysis: ResidualAnalysis,
    path: str | Path,
    output_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
    model_label: str | None = None,
) -> Path:
    """Write :func:`resid_figure` to a PNG file.

    Parameters
    ----------
    analysis, output_names, input_names, model_label
        As :func:`resid_figure`.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    return _save(resid_figure(analysis, output_names, input_names, model_label), path)


def resid_figure(
    analysis: ResidualAnalysis,
    output_names: Sequence[str] | None = None,
    input_names: Sequence[str] | None = None,
    model_label: str | None = None,
) -> Figure:
    """Plot residual autocorrelation and input-residual cross-correlation with 99 % bounds.

    Parameters
    ----------
    analysis : ResidualAnalysis
        Result of :func:`~.validation.resid`.
    output_names, input_names : sequence of str, optional
        Channel names for the titles.
    model_label : str, optional
        Name of the model, in the title.

    Returns
    -------
    Figure
        ``ny`` rows of ``nu + 1`` axes.
    """
    ny, nu = analysis.crosscorr.shape[:2]
    onames = list(output_names) if output_names else [f'y{i + 1}' for i in range(ny)]
    inames = list(input_names) if input_names else [f'u{j + 1}' for j in range(nu)]
    fig = Figure(figsize=(max(8.0, 3.4 * (nu + 1)), 1.0 + 2.8 * ny), layout='constrained')
    axes = fig.subplots(ny, nu + 1, squeeze=False)
    lags = analysis.lags
    for i in range(ny):
        # lag 0 of the autocorrelation is 1 by definition: left out, it would set the scale
        panels = [(lags[1:], analysis.autocorr[i, 1:], f'autocorrelation of e({onames[i]})')]
        for j in range(nu):
            x, values = lags, analysis.crosscorr[i, j]
            if analysis.feedback_corr is not None:  # lags -M..-1: the input after the residual
                back = analysis.feedback_corr[i, j, ::-1]
                x = np.r_[-lags[len(back) : 0 : -1], lags]
                values = np.r_[back, values]
            title = f'e({onames[i]}) vs input {inames[j]}'
            panels.append((x, values, title + '\n(lag < 0: input after residual, feedback)'))
        for ax, (x, values, title) in zip(axes[i], panels, strict=True):
            outside = np.abs(values) > analysis.bound
            ax.vlines(x[~outside], 0, values[~outside], lw=1.5, color='C0')
            ax.vlines(x[outside], 0, values[outside], lw=1.5, color='C3')
            ax.axhspan(-analysis.bound, analysis.bound, color='C0', alpha=0.15, label='99 % bound')
            ax.axhline(0, color='k', lw=0.5)
            ax.set_title(title, fontsize='medium')
            ax.set_xlabel('lag [samples]')
            ax.grid(True, lw=0.3)
            if x[0] < 0:
                ax.axvline(0, color='0.4', lw=0.8, ls=':')
    axes[0, 0].legend(loc='upper right', fontsize='small')
    verdict = textwrap.fill(analysis.summary(), width=int(fig.get_figwidth() * 11))
    head = f'{model_label}: ' if model_label else ''
    fig.suptitle(f'{head}residuals on validation data\n{verdict}', fontsize='medium')
    return fig


def bode_plot(
    models: Sequence[PolyModel],
    path: str | Path,
    labels: Sequence[str] | None = None,
    n_points: int = 400,
) -> Path:
    """Write :func:`bode_figure` to a PNG file.

    Parameters
    ----------
    models, labels, n_points
        As :func:`bode_figure`.
    path : str or Path
        PNG file to write.

    Returns
    -------
    Path
        The written file.
    """
    return _save(bode_figure(models, labels, n_points), path)


def bode_figure(
    models: Sequence[PolyModel],
    labels: Sequence[str] | None = None,
    n_points: int = 400,
) -> Figure:
    """Bode plot (magnitude in dB, phase in degrees) of every input-output channel.

    A channel without a path in any model (``nb = 0``: structurally zero) is
    labelled "no path" instead of being drawn.

    Parameters
    ----------
    models : sequence of PolyModel
        Models with equal ``ny``, ``nu`` and ``Ts``.
    labels : sequence of str, optional
        Legend names.
    n_points : int
        Frequencies, log-spaced up to Nyquist.

    Returns
    -------
    Figure
        Magnitude and phase axes per channel (rows ``2 i``, ``2 i + 1``, column ``j``).
    """
    labels = list(labels) if labels else [m.structure for m in models]
    first = models[0]
    nyq = 0.5 / first.Ts
    f = np.logspace(np.log10(nyq) - 3, np.log10(nyq), n_points)
    fig = Figure(figsize=(max(7.0, 5 * first.nu), 5.0 * first.ny), layout='constrained')
    axes = fig.subplots(2 * first.ny, first.nu, squeeze=False)
    responses = [model.freqresp(f) for model in models]
    for i in range(first.ny):
        yscale, yunit = display_scale(first.output_units[i] if first.output_units else '')
        for j in range(first.nu):
            mag_ax, phase_ax = axes[2 * i, j], axes[2 * i + 1, j]
            iunit = first.input_units[j] if first.input_units else ''
            gain = f' [dB {yunit}/{iunit}]' if yunit and iunit else ' [dB]'
            mag_ax.set_title(
                f'{first.input_names[j]} -> {first.output_names[i]}', fontsize='medium'
            )
            drawn = False
            for k, (model, H, label) in enumerate(zip(models, responses, labels, strict=True)):
                if not model.orders.nb[i, j] or not np.any(H[:, i, j]):
                    continue  # structurally zero: no path from this input
                drawn = True
                h = H[:, i, j] * yscale
                # a dash pattern each: curves on top of each other stay visible
                style = dict(color=f'C{k}', ls=DASHES[k % len(DASHES)], lw=1.6)
                mag_ax.semilogx(f, 20 * np.log10(np.abs(h)), label=label, **style)
                phase_ax.semilogx(f, np.degrees(np.unwrap(np.angle(h))), **style)
            if not drawn:
                for ax in (mag_ax, phase_ax):
                    ax.text(0.5, 0.5, 'no path (nb = 0)', ha='center', va='center',
                            transform=ax.transAxes, color='0.4')  # fmt: skip
                    ax.set_xscale('log')
                    ax.set_yticks([])  # nothing to read off an empty panel
            mag_ax.set_ylabel('magnitude' + gain)
            phase_ax.set_ylabel('phase [deg]')
            phase_ax.set_xlabel('frequency [Hz]')
            for ax in (mag_ax, phase_ax):
                ax.set_xlim(f[0], f[-1])
                ax.grid(True, which='both', lw=0.3)
    axes[0, 0].legend(fontsize='small')
    names = ', '.join(model_title(m, lab) for m, lab in zip(models, labels, strict=True))
    fig.suptitle(textwrap.fill(f'Bode plot of the identified models: {names}', width=100),
                 fontsize='medium')  # fmt: skip
    return fig
