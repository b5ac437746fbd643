"""Write a parameter set as a YAML file of the ``config/maggy_v2.yaml`` schema.

The file loads with :func:`maglev_ros.physics.load_parameters` (and so with
``make_model(path)``, the simulator's ``params`` parameter, ...) into exactly
the set that was written: floats are written with ``repr`` precision.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from ..physics.parameters import MaggyParameters

__all__ = ['parameters_to_mapping', 'write_parameters']


def _list(values) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).ravel()]


def _cylinders(cyl, extra: str) -> dict:
    return {
        'x': _list(cyl.centers[:, 0]),
        'y': _list(cyl.centers[:, 1]),
        'z': _list(cyl.centers[:, 2]),
        'radius': _list(cyl.radius),
        'length': _list(cyl.length),
        extra: _list(getattr(cyl, 'turns' if extra == 'turns' else 'polarization')),
    }


def parameters_to_mapping(params: MaggyParameters) -> dict:
    """Return the parameter document (the YAML schema as a dict) of a parameter set.

    Sensor rotation, gain and offset are written only where they differ from
    identity, 1 and 0.

    Parameters
    ----------
    params : MaggyParameters
        The parameter set.
    """
    m = params.magnet
    sensors = []
    for s in params.sensors:
        entry: dict = {'position': _list(s.position)}
        if not np.array_equal(s.rotation, np.eye(3)):
            entry['rotation'] = [_list(row) for row in s.rotation]
        if not np.all(s.gain == 1.0):
            entry['gain'] = _list(s.gain)
        if np.any(s.offset != 0.0):
            entry['offset'] = _list(s.offset)
        sensors.append(entry)
    c = params.coils
    correction = params.solenoid_radius_correction
    return {
        'name': params.name,
        'solenoids': _cylinders(params.solenoids, 'turns'),
        'permanent_magnets': _cylinders(params.permanent_magnets, 'polarization'),
        'levitating_magnet': {
            'radius': float(m.radius),
            'thickness': float(m.thickness),
            'polarization': float(m.polarization),
            'mass': float(m.mass),
            'inertia': _list(m.inertia),
        },
        'sensors': sensors,
        'workspace': {'min': _list(params.workspace.lower), 'max': _list(params.workspace.upper)},
        'coils': {
            'resistance': float(c.resistance),
            'inductance': float(c.inductance),
            'supply_voltage': float(c.supply_voltage),
        },
        'solenoid_radius_correction': None if correction is None else float(correction),
    }


def write_parameters(
    params: MaggyParameters, path: str | Path, header: Sequence[str] = ()
) -> Path:
    """Write ``params`` as a parameter YAML file.

    Parameters
    ----------
    params : MaggyParameters
        The set.
    path : str or Path
        Output file (parent directories are made).
    header : sequence of str
        Comment lines at the top (without ``#``), e.g. how the set was calibrated.

    Returns
    -------
    Path
        The file written.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    comments = ''.join(f'# {line}\n'.replace('# \n', '#\n') for line in header)
    body = yaml.safe_dump(
        parameters_to_mapping(params), sort_keys=False, width=99, default_flow_style=None
    )
    path.write_text(comments + body, encoding='utf-8')
    return path
