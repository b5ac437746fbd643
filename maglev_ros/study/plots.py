"""Figures of a study: success rate per parameter, region of attraction, worst runs.

Success rates carry 95 % Wilson intervals (the runs per point are few).
Curves are drawn per combination of the study's choices (parameter set,
controller, estimator, any grid value that is not a number).
"""

from __future__ import annotations

import os
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .parameters import PARAMETERS
from .results import wilson_interval
from .spec import StudySpec

__all__ = ['plot_region_of_attraction', 'plot_success', 'plot_worst', 'plot_study', 'worst_rows']

_X0 = ('x0.x', 'x0.y', 'x0.z', 'x0.alpha', 'x0.beta')
_SCALE = {'m': (1e3, 'mm'), 'T': (1e3, 'mT'), 'rad': (1e3, 'mrad'), '1': (100.0, '%')}
_RANK = {
    'crashed': 0,
    'controller_off': 1,
    'left_bounds': 2,
    'not_settled': 3,
    'error': 4,
    'ok': 5,
}


def _numeric(key: str) -> bool:
    return PARAMETERS[key].kind in ('number', 'integer')


def _style(j: int) -> dict:
    """Marker, size and line style of curve ``j``: curves on top of each other stay visible."""
    return {
        'marker': 'osD^v<>'[j % 7],
        'ms': max(9 - 1.5 * j, 3),
        'mfc': 'none',
        'ls': ('-', '--', '-.', ':')[j % 4],
        'lw': 1.3,
    }


def _pyplot():
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    return plt


def _scale(key: str) -> tuple[float, str]:
    unit = PARAMETERS[key].unit
    factor, shown = _SCALE.get(unit, (1.0, unit))
    label = key if not shown or shown == 'SI' else f'{key} ({shown})'
    return factor, label


def _groups(spec: StudySpec, rows: Sequence[dict[str, Any]], exclude: Sequence[str]):
    """Rows grouped by the grid's non-numeric keys (and numeric ones not in ``exclude``)."""
    keys = [k for k in spec.grid if k not in exclude and len(spec.grid[k]) > 1]
    keys = [k for k in keys if not _numeric(k)] + [k for k in keys if _numeric(k)]
    out: dict[tuple, list] = defaultdict(list)
    for r in rows:
        out[tuple(r[k] for k in keys)].append(r)
    return keys, out


def _label(keys: Sequence[str], group: tuple) -> str:
    if not keys:
        return 'all runs'
    return ', '.join(
        str(v) if isinstance(v, str) else f'{k.split(".")[-1]} {v}'
        for k, v in zip(keys, group, strict=True)
    )


def _rates(values: np.ndarray, success: np.ndarray, bins: np.ndarray | None):
    if bins is None:
        points = np.unique(values)
        index = np.searchsorted(points, values)
    else:
        index = np.clip(np.digitize(values, bins) - 1, 0, len(bins) - 2)
        points = 0.5 * (bins[:-1] + bins[1:])
    x, rate, low, high, count = [], [], [], [], []
    for i, p in enumerate(points):
        sel = index == i
        n = int(sel.sum())
        if not n:
            continue
        k = int(success[sel].sum())
        lo, hi = wilson_interval(k, n)
        x.append(p)
        rate.append(k / n)
        low.append(lo)
        high.append(hi)
        count.append(n)
    return np.array(x), np.array(rate), np.array(low), np.array(high), np.array(count)


def plot_success(
    spec: StudySpec, rows: Sequence[dict[str, Any]], key: str, path: str | os.PathLike
) -> Path:
    """Success rate against one numeric parameter (binned when drawn at random).

    Parameters
    ----------
    spec : StudySpec
    rows : sequence of dict
    key : str
        The parameter.
    path : path
        PNG to write.
    """
    plt = _pyplot()
    factor, xlabel = _scale(key)
    bins = None
    if key in spec.random:
        values = np.array([r[key] for r in rows], dtype=float)
        bins = np.linspace(values.min(), values.max(), 11) if values.size else None
    keys, groups = _groups(spec, rows, [key])
    counts: list[int] = []
    fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
    for j, (group, members) in enumerate(sorted(groups.items(), key=lambda g: str(g[0]))):
        v = np.array([r[key] for r in members], dtype=float)
        s = np.array([bool(r['success']) for r in members])
        x, rate, low, high, n = _rates(v, s, bins)
        line = ax.plot(x * factor, 100 * rate, label=_label(keys, group), **_style(j))[0]
        if n.size and n.min() >= 10:  # intervals say little with a handful of runs per point
            ax.fill_between(x * factor, 100 * low, 100 * high, color=line.get_color(), alpha=0.15)
        counts.extend(n)
    ax.set_xlabel(xlabel)
    ax.set_ylabel('success rate (%)')
    ax.set_ylim(-3, 103)
    ax.grid(alpha=0.3)
    ax.set_title(f'{spec.name}: success against {key}\n{_criterion(spec, counts)}', fontsize=9)
    if len(groups) > 1:
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def plot_region_of_attraction(
    spec: StudySpec, rows: Sequence[dict[str, Any]], path: str | os.PathLike
) -> Path | None:
    """Region of attraction over the initial-state grid (a rate curve for one axis, a map for two).

    Parameters
    ----------
    spec : StudySpec
    rows : sequence of dict
    path : path
        PNG to write.

    Returns
    -------
    Path or None
        None when the study has no initial-state grid.
    """
    axes_keys = [k for k in _X0 if k in spec.grid and len(spec.grid[k]) > 1]
    if not axes_keys:
        return None
    plt = _pyplot()
    keys, groups = _groups(spec, rows, axes_keys)
    items = sorted(groups.items(), key=lambda g: str(g[0]))
    if len(axes_keys) == 1:
        key = axes_keys[0]
        factor, xlabel = _scale(key)
        counts: list[int] = []
        fig, ax = plt.subplots(figsize=(6.4, 4.2), dpi=100)
        for j, (group, members) in enumerate(items):
            v = np.array([r[key] for r in members], dtype=float)
            s = np.array([bool(r['success']) for r in members])
            x, rate, _, _, n = _rates(v, s, None)
            counts.extend(n)
            recovered = x[rate == 1.0]
            unit = xlabel.rpartition('(')[2].rstrip(')')
            reach = (
                f': every run from |offset| <= {_reach(x, rate) * factor:.2f} {unit} recovers'
                if recovered.size
                else ': no offset recovers'
            )
            ax.plot(x * factor, 100 * rate, label=_label(keys, group) + reach, **_style(j))
        ax.set_xlabel(f'initial offset {xlabel}')
        ax.set_ylabel('recovered (%)')
        ax.set_ylim(-3, 103)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        ax.set_title(f'{spec.name}\n{_criterion(spec, counts)}', fontsize=9)
    else:
        kx, ky = axes_keys[:2]
        fx, lx = _scale(kx)
        fy, ly = _scale(ky)
        n = len(items)
        cols = min(n, 3)
        fig, axs = plt.subplots(
            (n + cols - 1) // cols,
            cols,
            figsize=(4.0 * cols + 1.2, 3.4 * ((n + cols - 1) // cols) + 0.9),
            dpi=100,
            squeeze=False,
            layout='constrained',
        )
        xs, ys = np.array(spec.grid[kx], float), np.array(spec.grid[ky], float)
        for index, (ax, (group, members)) in enumerate(zip(axs.flat, items, strict=False)):
            grid = np.zeros((len(ys), len(xs)))
            count = np.zeros_like(grid)
            for r in members:
                i, j = list(ys).index(r[ky]), list(xs).index(r[kx])
                grid[i, j] += bool(r['success'])
                count[i, j] += 1
            image = ax.pcolormesh(
                xs * fx,
                ys * fy,
                100 * grid / np.maximum(count, 1),
                cmap='RdYlGn',
                vmin=0,
                vmax=100,
                shading='nearest',
            )
            ax.set_xlabel(lx)
            if index % cols == 0:
                ax.set_ylabel(ly)
            ax.set_title(_label(keys, group), fontsize=9)
        for ax in list(axs.flat)[n:]:
            ax.set_visible(False)
        fig.colorbar(image, ax=axs, label='recovered (%)', shrink=0.8)
        counts = [int(c) for c in np.ravel(count)] if items else [0]
        fig.suptitle(f'{spec.name}: region of attraction\n{_criterion(spec, counts)}', fontsize=9)
    if len(axes_keys) == 1:
        fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def _value_text(key: str, value: Any) -> str:
    if isinstance(value, bool):
        return f'{key.split(".")[-1]} {value}'
    if not isinstance(value, (int, float)):
        return str(value)
    factor, label = _scale(key)
    unit = label.rpartition('(')[2].rstrip(')') if '(' in label else ''
    return f'{key.split(".")[-1]} {value * factor:.3g} {unit}'.rstrip()


def _criterion(spec: StudySpec, counts: Sequence[int]) -> str:
    """One line: the success criterion and the runs per point."""
    c = spec.success
    per = (
        f'{min(counts)}-{max(counts)}'
        if counts and min(counts) != max(counts)
        else (f'{counts[0]}' if counts else '0')
    )
    return (
        f'{per} runs per point. Success: no crash, |x|, |y|, |z - z_eq| <= {c.bound * 1e3:g} mm,'
        f'\nand their RMS <= {c.rms * 1e3:g} mm over the last {c.window:g} s'
    )


def _reach(x: np.ndarray, rate: np.ndarray) -> float:
    """Largest |offset| such that every grid offset with a smaller |offset| fully recovered."""
    order = np.argsort(np.abs(x))
    reach = 0.0
    for i in order:
        if rate[i] < 1.0:
            break
        reach = abs(x[i])
    return reach


def worst_rows(
    rows: Sequence[dict[str, Any]], count: int = 4, by: Sequence[str] = ()
) -> list[dict[str, Any]]:
    """Return the ``count`` worst runs: crashes first (earliest first), then by settled RMS.

    Parameters
    ----------
    rows : sequence of dict
    count : int
    by : sequence of str
        Keys whose every combination should show its worst run first (the
        controllers, the parameter sets, ...), so one failure mode does not
        fill the figure.
    """

    def badness(r):
        rms = max(r['rms_x'], r['rms_y'], r['rms_z'])
        crash = r['crash_time'] if r['crash_time'] == r['crash_time'] else np.inf
        return (_RANK.get(r['outcome'], 4), crash, -(rms if rms == rms else np.inf), r['run'])

    ranked = sorted((r for r in rows if r['outcome'] != 'error'), key=badness)
    if not by:
        return ranked[:count]
    firsts: dict[tuple, dict] = {}
    for r in ranked:  # the worst of each group first, then the worst of the rest
        firsts.setdefault(tuple(r[k] for k in by), r)
    chosen = sorted(firsts.values(), key=badness)[:count]
    rest = [r for r in ranked if all(r is not c for c in chosen)]
    return chosen + rest[: count - len(chosen)]


def plot_worst(
    spec: StudySpec, rows: Sequence[dict[str, Any]], path: str | os.PathLike, count: int = 4
) -> Path | None:
    """Trajectories of the worst runs, simulated again here from their seeds.

    Parameters
    ----------
    spec : StudySpec
    rows : sequence of dict
    path : path
        PNG to write.
    count : int
        Runs shown.
    """
    from .loop_adapter import simulate

    by = [k for k in spec.grid if not _numeric(k) and len(spec.grid[k]) > 1]
    worst = worst_rows(rows, count, by)
    if not worst:
        return None
    plt = _pyplot()
    fig, axs = plt.subplots(3, 1, figsize=(7.0, 6.4), dpi=100, sharex=True)
    bound = spec.success.bound * 1e3
    for r in worst:
        values = {k: r[k] for k in spec.keys}
        result = simulate(values, r['seed'], spec.duration)
        err = result.position_error() * 1e3
        varied = ', '.join(_value_text(k, r[k]) for k in [*spec.grid, *spec.random])
        label = f'run {r["run"]} ({r["outcome"]}): {varied}'
        for i, ax in enumerate(axs):
            ax.plot(result.t, err[:, i], lw=1, label=label if i == 0 else None)
    for ax, name in zip(axs, ('x', 'y', 'z - z_eq'), strict=True):
        ax.axhline(bound, color='k', ls=':', lw=0.8)
        ax.axhline(-bound, color='k', ls=':', lw=0.8)
        ax.set_ylabel(f'{name} (mm)')
        ax.set_ylim(-2.5 * bound, 2.5 * bound)
        ax.grid(alpha=0.3)
    axs[-1].set_xlabel('t (s)')
    axs[0].legend(fontsize=7, loc='upper right')
    axs[0].set_title(f'{spec.name}: the {len(worst)} worst runs (dotted: the bound)', fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return Path(path)


def plot_study(
    spec: StudySpec, rows: Sequence[dict[str, Any]], out: str | os.PathLike
) -> list[Path]:
    """Write every figure of a study into ``out``; return the files.

    Parameters
    ----------
    spec : StudySpec
    rows : sequence of dict
    out : path
        Directory.
    """
    out = Path(out)
    paths = []
    if not rows:
        return paths
    roa = plot_region_of_attraction(spec, rows, out / 'region_of_attraction.png')
    if roa:
        paths.append(roa)
    for key in [*spec.grid, *spec.random]:
        if key in _X0 or not _numeric(key):
            continue
        if key in spec.grid and len(spec.grid[key]) < 2:
            continue
        paths.append(
            plot_success(spec, rows, key, out / f'success_vs_{key.replace(".", "_")}.png')
        )
    worst = plot_worst(spec, rows, out / 'worst_runs.png')
    if worst:
        paths.append(worst)
    return paths
