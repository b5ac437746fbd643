"""Figures of the ROS-free closed loop in issue 9's set-up (what the tests assert, printed).

Set-up: V2 and V4, true torque, rigid kinematics, sensor noise 0.1 mT per axis,
quantisation 0.098 mT, one sample of sensor delay, coil dynamics, 1.0 A limit,
command one sample late. Start: 0.5 mm off in x, y, z and 1 deg of tilt (V4:
0.3 mm, 0.5 deg). Cost: CPU time per loop step (simulator + estimator +
controller + recording).

Usage::

    python benchmarks/closed_loop_figures.py           # everything (several minutes)
    python benchmarks/closed_loop_figures.py --hold 10 --only hold
    python benchmarks/closed_loop_figures.py --only ekf ukf --ekf-hold 60 --ukf-hold 60  # 60 s
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from maglev_ros.control import ControllerConfig
from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.estimation import EstimatorConfig
from maglev_ros.physics import SensorFreeze, linearize, load_parameters, make_model

START = {'maggy_v2': (0.5e-3, np.deg2rad(1.0)), 'maggy_v4': (0.3e-3, np.deg2rad(0.5))}


def start(loop, name, scale=1.0):
    """Return the issue's initial state for ``name`` (scaled), at the plant's equilibrium."""
    offset, tilt = START[name]
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    x0[:3] += scale * offset
    x0[3:5] = scale * tilt
    return x0


def um(v) -> str:
    """Format metres as micrometres."""
    return ' '.join(f'{1e6 * x:6.1f}' for x in np.atleast_1d(v))


def run(loop, duration, **kw):
    """Run and return (result, CPU us per step)."""
    t = time.process_time()
    r = loop.run(duration, **kw)
    return r, (time.process_time() - t) / max(len(r.t), 1) * 1e6


def hold(name, model, lin, seconds, kind='kf'):
    """Run settle and hold; print consistency and NIS."""
    loop = make_closed_loop(model, linear=lin, estimator=EstimatorConfig(filter=kind))
    r, cpu = run(loop, seconds, x0=start(loop, name))
    if r.crashed:
        print(f'{name} {kind} hold: CRASHED {r.reason}')
        return
    ts = r.settle_time()
    rms, worst = r.hold(ts)
    inside = r.consistency(ts)
    total, band = r.nis_average(ts)
    _, windows = r.nis_windows(ts)
    print(
        f'{name} {kind.upper()}+LQR {seconds:.0f} s: settle {ts:.3f} s; '
        f'hold RMS x y z {um(rms)} um, max {um(worst)} um; '
        f'within 3 sigma {np.round(inside, 4)}; NIS {total:.0f} in '
        f'[{band[0]:.0f}, {band[1]:.0f}]; 0.1 s windows in band {np.mean(windows):.3f}; '
        f'{cpu:.0f} us CPU/step',
        flush=True,
    )


def step(name, model, lin):
    """Run a 0.25 mm x step at 0.5 s."""
    loop = make_closed_loop(model, linear=lin)
    x_eq = loop.estimator.x_eq[:3]
    r, _ = run(loop, 3.5, reference=lambda t: x_eq + [2.5e-4, 0, 0] if t >= 0.5 else x_eq)
    n = int(round(0.02 / r.dt))
    smooth = np.convolve(r.x[:, 0] - x_eq[0], np.ones(n) / n, mode='same')
    reached = r.t[(r.t >= 0.5) & (smooth >= 0.9 * 2.5e-4)]
    err = (r.x[:, 0] - r.reference[:, 0])[r.t >= 1.0]
    print(
        f'{name} step 0.25 mm: 90 % (20 ms mean) after {reached[0] - 0.5:.3f} s; '
        f'mean error after 0.5 s {um(np.mean(err))} um, RMS {um(np.sqrt(np.mean(err**2)))} um',
        flush=True,
    )


def faults(name, model, lin):
    """Run sensor 1 frozen 100 ms at 1 s, and the estimator input cut 50 ms at 1 s."""
    loop = make_closed_loop(model, linear=lin, freeze=SensorFreeze(schedule=((1, 1.0, 0.1),)))
    r, _ = run(loop, 2.0, x0=start(loop, name))
    rms, worst = r.hold(0.8)
    msgs = [m for m in r.messages if 'frozen' in m]
    print(
        f'{name} sensor 1 frozen 0.1 s: crashed {r.crashed}; RMS {um(rms)} um, max {um(worst)} '
        f'um from 0.8 s; diagnostics: {msgs[:2]}',
        flush=True,
    )
    loop = make_closed_loop(model, linear=lin)
    r, _ = run(loop, 1.5, x0=start(loop, name), cut=(1.0, 0.05))
    safe = np.flatnonzero((r.t >= 1.0) & (r.level == 'ERROR'))
    first = r.t[safe[0]] - 1.0 if safe.size else float('nan')
    err = [m for m in r.messages if 'ERROR' in m]
    print(
        f'{name} input cut 50 ms: ERROR and zero currents {1e3 * first:.1f} ms after the cut; '
        f'crashed {r.crashed} {r.reason}; message: {err[:1]}',
        flush=True,
    )


def mismatch(name, model, lin, seconds):
    """Run the plant with polarisation and mass +-10 %, from rest.

    Estimators: bias states (what the test uses), none, and the magnet-strength
    state. Printed: hold from 1 s, and the commands that hit the limit.
    """
    p = load_parameters(name)
    estimators = {
        'bias states': EstimatorConfig(bias_states=True),
        'no offset states': EstimatorConfig(),
        'magnet strength': EstimatorConfig(magnet_strength=True),
    }
    for fj, fm in ((1.1, 1.1), (0.9, 0.9), (1.1, 0.9), (0.9, 1.1)):
        magnet = dataclasses.replace(
            p.magnet, polarization=p.magnet.polarization * fj, mass=p.magnet.mass * fm
        )
        plant = make_model(p.replace(magnet=magnet, solenoid_radius_correction=model.correction))
        for label, config in estimators.items():
            loop = make_closed_loop(model, plant=plant, linear=lin, estimator=config)
            r, _ = run(loop, seconds, x0=start(loop, name, 0.0))
            head = f'{name} J x{fj} m x{fm} {label}:'
            if r.crashed:
                print(f'{head} CRASHED {r.reason}', flush=True)
                continue
            rms, worst = r.hold(1.0)
            extra = ''
            if config.magnet_strength:
                extra = f'; strength estimate {loop.estimator.strength:+.3f}'
            print(
                f'{head} RMS {um(rms)} um, max {um(worst)} um; '
                f'{loop.controller.saturated} commands at the limit{extra}',
                flush=True,
            )


def pd(model, lin):
    """Run the firmware's PD from the V2 offset."""
    loop = make_closed_loop(model, linear=lin, controller=ControllerConfig(mode='pd'))
    r, _ = run(loop, 5.0, x0=start(loop, 'maggy_v2'))
    if r.crashed:
        print(f'maggy_v2 PD: CRASHED {r.reason}')
        return
    err = r.position_error()[r.t >= 2.0]
    print(
        f'maggy_v2 PD 5 s: RMS x y z from 2 s {um(np.sqrt(np.mean(err**2, axis=0)))} um '
        f'(z is not controlled by the PD), max {um(np.max(np.abs(err), axis=0))} um',
        flush=True,
    )


def main(argv=None) -> int:
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--hold', type=float, default=60.0, help='KF hold, s')
    parser.add_argument('--mismatch', type=float, default=10.0, help='mismatch runs, s')
    parser.add_argument('--ekf-hold', type=float, default=10.0, help='EKF hold (V2), s')
    parser.add_argument('--ukf-hold', type=float, default=2.0, help='UKF hold (V2), s')
    parser.add_argument(
        '--only', nargs='+', default=['hold', 'step', 'faults', 'mismatch', 'ekf', 'ukf', 'pd']
    )
    args = parser.parse_args(argv)
    for name in ('maggy_v2', 'maggy_v4'):
        model = make_model(name)
        lin = linearize(model)
        if 'hold' in args.only:
            hold(name, model, lin, args.hold)
        if 'step' in args.only:
            step(name, model, lin)
        if 'faults' in args.only:
            faults(name, model, lin)
        if 'mismatch' in args.only:
            mismatch(name, model, lin, args.mismatch)
        if name == 'maggy_v2':
            if 'ekf' in args.only:
                hold(name, model, lin, args.ekf_hold, 'ekf')
            if 'ukf' in args.only:
                hold(name, model, lin, args.ukf_hold, 'ukf')
            if 'pd' in args.only:
                pd(model, lin)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
