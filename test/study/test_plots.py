"""Figures from rows: the region-of-attraction map over two initial-state axes."""

from __future__ import annotations

import itertools

from maglev_ros.study import study_from_mapping
from maglev_ros.study.plots import plot_region_of_attraction, plot_success, worst_rows


def _rows(spec):
    rows = []
    grid = spec.grid
    for i, (c, x, b) in enumerate(
        itertools.product(grid['controller'], grid['x0.x'], grid['x0.beta'])
    ):
        ok = abs(x) / 0.7e-3 + abs(b) / 0.02 <= 1.0 + 0.5 * (c == 'lqr')
        rows.append(
            {
                'run': i,
                'seed': i,
                'controller': c,
                'x0.x': x,
                'x0.beta': b,
                'success': ok,
                'outcome': 'ok' if ok else 'crashed',
                'rms_x': 1e-5 if ok else float('nan'),
                'rms_y': 1e-5 if ok else float('nan'),
                'rms_z': 1e-6 if ok else float('nan'),
                'crash_time': float('nan') if ok else 0.1 + abs(x) * 10,
            }
        )
    return rows


def test_a_two_axis_map_and_a_rate_curve(tmp_path):
    spec = study_from_mapping(
        {
            'duration': 1.0,
            'grid': {
                'controller': ['lqr', 'pd'],
                'x0.x': {'start': -1e-3, 'stop': 1e-3, 'num': 9},
                'x0.beta': {'start': -0.03, 'stop': 0.03, 'num': 7},
            },
        }
    )
    rows = _rows(spec)
    path = plot_region_of_attraction(spec, rows, tmp_path / 'roa.png')
    assert path.read_bytes()[:4] == b'\x89PNG'
    curve = plot_success(spec, rows, 'x0.beta', tmp_path / 'beta.png')
    assert curve.stat().st_size > 10_000
    worst = worst_rows(rows, 3, ['controller'])
    assert {r['controller'] for r in worst} == {'lqr', 'pd'}  # each controller's worst first
    assert all(not r['success'] for r in worst)
    # no initial-state grid: no map
    plain = study_from_mapping({'duration': 1.0, 'grid': {'controller': ['lqr', 'pd']}})
    assert plot_region_of_attraction(plain, rows, tmp_path / 'none.png') is None
