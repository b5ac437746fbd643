"""Save and load identified models (JSON, YAML) and export them to MATLAB ``.mat``.

The file holds the structure, sample time, orders, parameter vector, covariance,
noise variance, channel labels, the estimation report and - for readers that do
not want to decode the parameter layout - every polynomial trimmed to its order
(coefficients of ``q^0, q^-1, ...``; ``B`` includes its ``nk`` leading zeros).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from .model import EstimationReport, PolyModel
from .orders import make_orders

__all__ = ['export_mat', 'load_model', 'model_from_dict', 'model_to_dict', 'save_model']

FORMAT_VERSION = 1


def model_to_dict(model: PolyModel) -> dict[str, Any]:
    """Return a JSON-serializable description of a model.

    Parameters
    ----------
    model : PolyModel
        Model to describe.

    Returns
    -------
    dict
        Plain Python types only.
    """
    ny, nu = model.ny, model.nu
    polys = {
        'A': [[model.polynomial('A', i, j).tolist() for j in range(ny)] for i in range(ny)],
        'B': [[model.polynomial('B', i, j).tolist() for j in range(nu)] for i in range(ny)],
        'C': [model.polynomial('C', i).tolist() for i in range(ny)],
        'D': [model.polynomial('D', i).tolist() for i in range(ny)],
        'F': [[model.polynomial('F', i, j).tolist() for j in range(nu)] for i in range(ny)],
    }
    out: dict[str, Any] = {
        'format': 'maglev_ros.sysid.PolyModel',
        'version': FORMAT_VERSION,
        'structure': model.structure,
        'Ts': model.Ts,
        'orders': model.orders.as_dict(),
        'theta': model.theta.tolist(),
        'polynomials': polys,
        'noise_variance': model.noise_variance.tolist(),
        'covariance': None if model.covariance is None else model.covariance.tolist(),
        'output_names': list(model.output_names),
        'input_names': list(model.input_names),
        'output_units': list(model.output_units),
        'input_units': list(model.input_units),
        'stable': model.is_stable,
    }
    if model.report is not None:
        r = model.report
        out['report'] = {
            'method': r.method,
            'n_samples': r.n_samples,
            'fit': r.fit.tolist(),
            'mse': r.mse.tolist(),
            'fpe': r.fpe,
            'aic': r.aic,
            'iterations': r.iterations,
            'converged': r.converged,
            'max_iter': r.max_iter,
        }
    return out


def model_from_dict(d: dict[str, Any]) -> PolyModel:
    """Rebuild a model from :func:`model_to_dict` output.

    Parameters
    ----------
    d : dict
        Description.

    Returns
    -------
    PolyModel
        The model.
    """
    try:
        o = d['orders']
        ny, nu = len(o['na']), len(o['nb'][0]) if o['nb'] else 0
        orders = make_orders(ny, nu, o['na'], o['nb'], o['nk'], o['nc'], o['nd'], o['nf'])
        report = None
        if d.get('report'):
            r = d['report']
            report = EstimationReport(
                r['method'],
                int(r['n_samples']),
                np.asarray(r['fit']),
                np.asarray(r['mse']),
                float(r['fpe']),
                float(r['aic']),
                int(r.get('iterations', 0)),
                bool(r.get('converged', True)),
                int(r.get('max_iter', 0)),
            )
        cov = d.get('covariance')
        return PolyModel(
            d['structure'],
            orders,
            np.asarray(d['theta'], dtype=float),
            float(d['Ts']),
            np.asarray(d['noise_variance'], dtype=float),
            None if cov is None else np.asarray(cov, dtype=float),
            tuple(d.get('output_names', ())),
            tuple(d.get('input_names', ())),
            tuple(d.get('output_units', ())),
            tuple(d.get('input_units', ())),
            report,
        )
    except KeyError as exc:
        raise ValueError(f'model description lacks the field {exc.args[0]!r}') from None


def save_model(model: PolyModel, path: str | Path) -> Path:
    """Write a model to ``.json``, ``.yaml``/``.yml`` or ``.mat`` (by extension).

    Parameters
    ----------
    model : PolyModel
        Model to save.
    path : str or Path
        Output file.

    Returns
    -------
    Path
        The written file.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == '.json':
        path.write_text(json.dumps(model_to_dict(model), indent=1))
    elif suffix in ('.yaml', '.yml'):
        import yaml

        path.write_text(yaml.safe_dump(model_to_dict(model), sort_keys=False))
    elif suffix == '.mat':
        export_mat(model, path)
    else:
        raise ValueError(
            f'model file extension must be .json, .yaml, .yml or .mat, got {path.name!r}'
        )
    return path


def load_model(path: str | Path) -> PolyModel:
    """Read a model saved by :func:`save_model` as JSON or YAML.

    Parameters
    ----------
    path : str or Path
        ``.json``, ``.yaml`` or ``.yml`` file.

    Returns
    -------
    PolyModel
        The model.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f'model file {str(path)!r} does not exist')
    suffix = path.suffix.lower()
    if suffix == '.json':
        d = json.loads(path.read_text())
    elif suffix in ('.yaml', '.yml'):
        import yaml

        d = yaml.safe_load(path.read_text())
    else:
        raise ValueError(f'can load .json or .yaml models, got {path.name!r}')
    if not isinstance(d, dict) or d.get('format') != 'maglev_ros.sysid.PolyModel':
        raise ValueError(f'{str(path)!r} is not a maglev_ros sysid model file')
    return model_from_dict(d)


def export_mat(model: PolyModel, path: str | Path) -> Path:
    """Export polynomials to a MATLAB ``.mat`` file (for ``idpoly`` in MATLAB).

    Variables: ``A`` (ny x ny cell), ``B``, ``F`` (ny x nu cells), ``C``, ``D``
    (ny x 1 cells), ``Ts``, ``NoiseVariance``, ``structure``, ``theta`` and the
    order matrices; rebuild with ``idpoly(A, B, C, D, F, NoiseVariance, Ts)``.

    Parameters
    ----------
    model : PolyModel
        Model to export.
    path : str or Path
        Output ``.mat`` file.

    Returns
    -------
    Path
        The written file.
    """
    from scipy.io import savemat

    d = model_to_dict(model)

    def cell(rows: list) -> np.ndarray:
        flat = [
            [
                np.asarray(p, dtype=float)[None, :]
                for p in (row if isinstance(row[0], list) else [row])
            ]
            for row in rows
        ]
        out = np.empty((len(flat), len(flat[0])), dtype=object)
        for i, row in enumerate(flat):
            for j, p in enumerate(row):
                out[i, j] = p
        return out

    polys = d['polynomials']
    content = {
        key: cell(polys[key])
        for key in ('A', 'B', 'C', 'D', 'F')
        if polys[key] and polys[key][0] != []
    }
    content.update(
        {
            'Ts': model.Ts,
            'NoiseVariance': model.noise_variance,
            'structure': model.structure,
            'theta': model.theta,
        }
    )
    content.update({k: np.asarray(v, dtype=float) for k, v in d['orders'].items()})
    path = Path(path)
    savemat(path, content)
    return path
