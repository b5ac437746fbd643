"""The largest initial x offset each parameter set recovers from (KF + LQR, issue set-up).

Set-up as the closed-loop tests: true torque, rigid kinematics, sensor noise
0.1 mT, quantisation 0.098 mT, one sample of sensor delay, coil dynamics,
1.0 A limit, command one sample late; the magnet starts at rest, displaced
by ``d`` in x only (y = z offset = tilt = 0), the estimator at the equilibrium.
*Recovered*: no crash, and over the run's last 0.5 s the RMS of x, y and
z - z_eq is below 0.1 mm. The largest such ``d`` is found by bisection (the
run is 2 s; resolution 10 um), for each seed given; a smaller offset is checked
too, so a non-monotonic boundary shows up as a failure below the reported one.

Usage::

    python benchmarks/recovery.py                 # both sets, seeds 0 1 2
    python benchmarks/recovery.py --params maggy_v4 --seeds 0
"""

from __future__ import annotations

import argparse

import numpy as np

from maglev_ros.control.closed_loop import make_closed_loop
from maglev_ros.physics import linearize, make_model


def recovers(loop, d: float, duration: float = 2.0) -> bool:
    """Return True when the loop recovers from an x offset of ``d`` (m)."""
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    x0[0] += d
    r = loop.run(duration, x0=x0)
    if r.crashed:
        return False
    rms, _ = r.hold(duration - 0.5)
    return bool(np.all(rms < 1e-4))


def largest(loop, low: float = 0.1e-3, high: float = 3.0e-3, resolution: float = 10e-6) -> float:
    """Bisect the largest recovered x offset, m (``low`` must recover)."""
    if not recovers(loop, low):
        return 0.0
    while high - low > resolution:
        mid = 0.5 * (low + high)
        if recovers(loop, mid):
            low = mid
        else:
            high = mid
    return low


def main(argv=None) -> int:
    """Measure and print the largest recovered offset per parameter set and seed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params', nargs='+', default=['maggy_v2', 'maggy_v4'])
    parser.add_argument('--seeds', nargs='+', type=int, default=[0, 1, 2])
    args = parser.parse_args(argv)
    for name in args.params:
        model = make_model(name)
        linear = linearize(model)
        found = []
        for seed in args.seeds:
            loop = make_closed_loop(model, linear=linear, seed=seed)
            d = largest(loop)
            below = recovers(loop, 0.8 * d) if d else False
            found.append(d)
            print(
                f'{name} seed {seed}: recovers from x = {d * 1e3:.2f} mm '
                f'(and from 0.8 of it: {below})',
                flush=True,
            )
        print(f'{name}: smallest over seeds {min(found) * 1e3:.2f} mm', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
