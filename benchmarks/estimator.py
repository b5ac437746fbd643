"""Estimator cost per sample against one simulator step, and against filterpy, in one run.

Data: 2,000 samples (0.4 s at 5 kHz) of the V2 closed loop (KF + LQR, sensor
noise 0.1 mT, quantisation 0.098 mT, one sample of delay, coil dynamics),
recorded once; every filter then processes the same readings and currents.

Yardstick: one simulator sample step, the package's compiled RK4 sample step
(``physics.kernels.sample_step`` through the simulator's entry point: one
RK4 step of the fast model, coil electrics, crash check, readings) on the
same model, timed over the recorded commands.

Filters (defaults: gate, freeze check, delay, ``prediction='fast'``), each
through ``Estimator.step`` one sample at a time (one compiled call a sample):

* KF against ``filterpy.kalman.KalmanFilter`` ``update`` + ``predict`` with the
  same F, B, H, Q, R (filterpy has no gate and no freeze check); agreement of
  the published estimates, relative to their largest value.
* EKF and UKF against filterpy's ``ExtendedKalmanFilter`` and
  ``UnscentedKalmanFilter`` on the full model
  (:class:`~maglev_ros.estimation.reference.FilterpyReference`: one RK4 step
  per sample or sigma point, Jacobians by central differences every sample).
  Accuracy of the fast filter: the largest ``|ours - reference| / sigma``
  over samples and reduced states (sigma the reference's); agreement of the
  same filter with ``prediction='full'`` (relative).

The composed loop (:class:`~maglev_ros.loop.ControlLoop`), in lockstep and
in real time. "Each under half a core" is the estimator's own share: the
thread CPU time spent inside ``Estimator.step`` per sample times 5,000
samples a second (the loop's other work, the plant and the controller, is
not the estimator's; the whole loop's share is printed next to it).

* lockstep: :class:`~maglev_ros.control.closed_loop.ClosedLoop` (a
  ``ControlLoop`` on the simulator, stepped as fast as it goes) for
  ``--loop-seconds`` of simulated time;
* real time: the loop node's loop without ROS
  (:func:`~maglev_ros.loop.build_simulated_loop`: the simulator paced by
  the wall clock, 5 kHz samples in 1 ms bursts, the LQR at 1 kHz) for
  ``--realtime-seconds`` of wall time; its real-time factor and overruns
  too. The real-time loop ran when the magnet was held for the whole run.

Cost: the best of ``--repeat`` runs of CPU time (``time.thread_time``) per
sample, single-threaded BLAS. The 5 kHz budget is 200 us per sample for the
whole loop (simulator or driver, estimator, controller). On a shared machine
expect noise; the ratios are measured in the same run.

Usage::

    python benchmarks/estimator.py            # about a minute with a warm numba cache
    python benchmarks/estimator.py --markdown table.md
"""

from __future__ import annotations

import os

os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
os.environ.setdefault('OMP_NUM_THREADS', '1')

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from maglev_ros.control.closed_loop import make_closed_loop  # noqa: E402
from maglev_ros.estimation import EstimatorConfig, make_estimator  # noqa: E402
from maglev_ros.estimation.reference import FilterpyReference  # noqa: E402
from maglev_ros.physics import linearize, make_model  # noqa: E402

N = 2000
#: the issue's bars: KF speed-up over filterpy, EKF and UKF in simulator steps
KF_SPEEDUP, EKF_STEPS, UKF_STEPS = 5.0, 2.0, 8.0
KF_AGREE, FULL_AGREE, SIGMA = 1e-9, 1e-6, 0.1


def record(model, linear):
    """Record a short closed-loop run: readings (N, 9), currents (N, 4), applied drives (N, 4)."""
    loop = make_closed_loop(model, linear=linear)
    ys, cs, ds = [], [], []
    sim, est, ctrl = loop.simulator, loop.estimator, loop.controller
    y = sim.reset()
    pending = np.zeros(4)
    for k in range(N):
        i = sim.currents
        ys.append(y)
        cs.append(i)
        command = ctrl.command(k * sim.dt, est.step(y, i), i)
        pending, applied = command, pending
        ds.append(applied)
        y = sim.step(applied)
    return np.array(ys), np.array(cs), np.array(ds), loop.simulator


def best_cpu(run, repeat: int) -> float:
    """Return the best CPU time of ``repeat`` runs, s."""
    best = np.inf
    for _ in range(repeat):
        t = time.thread_time()
        run()
        best = min(best, time.thread_time() - t)
    return best


def simulator_step(sim, drives):
    """Return a run of the simulator's compiled sample step over ``drives``."""
    step, args = sim._sample_step, sim._step_args

    def run():
        xe = sim._xe
        for d in drives:
            xe, _, _ = step(xe, d, *args)

    return run


def estimator_run(est, ys, cs, out=None):
    """Return a run of ``est.step`` over the data (estimates, covariances into ``out``)."""

    def run():
        est.reset()
        for k, (y, i) in enumerate(zip(ys, cs, strict=True)):
            x = est.step(y, i)
            if out is not None:
                out[0][k] = (x - est.x_eq)[est.reduced]
                out[1][k] = est._out_p[: est.n_reduced, : est.n_reduced]

    return run


def reference_run(ref, ys, cs, out=None):
    """Return a run of the filterpy reference (into ``out`` as :func:`estimator_run`)."""
    nr = ref.est.n_reduced

    def run():
        ref.reset()
        for k, (y, i) in enumerate(zip(ys, cs, strict=True)):
            x, p = ref.step(y, i)
            if out is not None:
                out[0][k] = x[:nr]
                out[1][k] = p[:nr, :nr]

    return run


def storage(n):
    """Arrays for a run's estimates (n, 10) and covariances (n, 10, 10)."""
    return np.empty((n, 10)), np.empty((n, 10, 10))


def in_the_loop(model, linear, kind, seconds):
    """Estimator CPU per sample inside ``ClosedLoop`` at 5 kHz, and the whole loop's, s."""
    loop = make_closed_loop(model, estimator=EstimatorConfig(filter=kind), linear=linear)
    est = loop.estimator
    step = est.step
    spent = [0.0]

    def timed_step(y, currents):
        t = time.thread_time()
        x = step(y, currents)
        spent[0] += time.thread_time() - t
        return x

    est.step = timed_step  # this instance only: the loop calls est.step
    loop.run(0.05)  # warm up
    spent[0] = 0.0
    t = time.thread_time()
    result = loop.run(seconds)
    total = time.thread_time() - t
    n = len(result.t)
    if result.crashed:
        raise RuntimeError(f'the {kind.upper()} loop crashed: {result.reason}')
    return spent[0] / n, total / n


def in_real_time(kind, seconds):
    """Estimator CPU per sample in the real-time composed loop, the loop's share, RTF, overruns."""
    from maglev_ros.loop import SimulatedLoopSettings, build_simulated_loop

    settings = SimulatedLoopSettings(filter=kind)
    loop, plant = build_simulated_loop(settings)
    est = loop.estimator
    step = est.step
    spent = [0.0, 0]

    def timed_step(y, currents):
        t = time.thread_time()
        x = step(y, currents)
        spent[0] += time.thread_time() - t
        spent[1] += 1
        return x

    est.step = timed_step  # this instance only: the loop calls est.step
    samples = int(seconds * settings.sample_rate)
    cpu, wall = time.process_time(), time.monotonic()
    loop.run(samples)
    cpu, wall = time.process_time() - cpu, time.monotonic() - wall
    return {
        'estimator': spent[0] / max(spent[1], 1),
        'loop_share': cpu / wall,
        'rtf': plant.real_time_factor,
        'overruns': plant.overruns,
        'held': not loop.stopped,
    }


def relative(a, b) -> float:
    """Largest |a - b| relative to the largest |b|."""
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def in_sigma(a, ref) -> float:
    """Largest |a - reference| in the reference's standard deviations."""
    std = np.sqrt(np.einsum('kii->ki', ref[1]))
    return float(np.max(np.abs(a[0] - ref[0]) / std))


def verdict(ok: bool) -> str:
    return 'ok' if ok else 'NOT MET'


def main(argv=None) -> int:
    """Run the comparison, print the table and the checks; exit 1 when a check fails."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=3, help='runs per filter (best counts)')
    parser.add_argument('--markdown', help='also write the table to this file')
    parser.add_argument(
        '--loop-seconds', type=float, default=1.0, help='simulated s of each lockstep loop'
    )
    parser.add_argument(
        '--realtime-seconds', type=float, default=5.0, help='wall s of each real-time loop'
    )
    args = parser.parse_args(argv)
    model = make_model('maggy_v2')
    linear = linearize(model)
    print(f'recording {N} samples of the V2 closed loop ...', flush=True)
    ys, cs, ds, sim = record(model, linear)
    sim_run = simulator_step(sim, ds)
    sim_run()
    t_sim = best_cpu(sim_run, args.repeat) / N
    print(f'simulator sample step (RK4, coil electrics, readings): {t_sim * 1e6:.1f} us')
    rows, checks = [], []
    for kind in ('kf', 'ekf', 'ukf'):
        est = make_estimator(model, EstimatorConfig(filter=kind), linear=linear)
        ref = FilterpyReference(
            make_estimator(model, EstimatorConfig(filter=kind, prediction='full'), linear=linear)
        )
        mine, theirs = storage(N), storage(N)
        estimator_run(est, ys, cs, mine)()  # compile / warm up, and the estimates
        rejected = sum(est.status().rejected)
        t_ours = best_cpu(estimator_run(est, ys, cs), args.repeat) / N
        reference_run(ref, ys, cs, theirs)()
        n_ref = N if kind != 'ukf' else N // 4  # filterpy's UKF: a quarter is enough to time
        t_ref = best_cpu(reference_run(ref, ys[:n_ref], cs[:n_ref]), args.repeat) / n_ref
        if kind == 'kf':
            agree = relative(mine[0], theirs[0])

            def burst(est=est):
                est.reset()
                est.step_many(ys, cs)

            t_many = best_cpu(burst, args.repeat) / N
            accuracy = (
                f'agree {agree:.1e} rel; step_many {t_many * 1e6:.1f} us ({t_ref / t_many:.1f}x)'
            )
            checks.append(
                (
                    f'KF {t_ref / t_ours:.1f}x faster than filterpy (>= {KF_SPEEDUP:g}x), agree '
                    f'{agree:.1e} (<= {KF_AGREE:g}; {rejected} gated out)',
                    t_ref / t_ours >= KF_SPEEDUP and agree <= KF_AGREE,
                )
            )
        else:
            full = make_estimator(
                model, EstimatorConfig(filter=kind, prediction='full'), linear=linear
            )
            full_out = storage(N)
            estimator_run(full, ys, cs, full_out)()
            agree = max(relative(full_out[0], theirs[0]), relative(full_out[1], theirs[1]))
            sigma = in_sigma(mine, theirs)
            accuracy = f'fast {sigma:.1e} sigma; full agree {agree:.1e} rel'
            bar = EKF_STEPS if kind == 'ekf' else UKF_STEPS
            checks.append(
                (
                    f'{kind.upper()} {t_ours / t_sim:.2f} simulator steps (<= {bar:g})',
                    t_ours / t_sim <= bar,
                )
            )
            checks.append(
                (
                    f'{kind.upper()} fast within {sigma:.1e} sigma of the full-model filterpy '
                    f'reference (<= {SIGMA:g})',
                    sigma <= SIGMA,
                )
            )
            checks.append(
                (
                    f'{kind.upper()} full model agrees with filterpy to {agree:.1e} '
                    f'(<= {FULL_AGREE:g})',
                    agree <= FULL_AGREE,
                )
            )
        rows.append((kind, t_ours, t_ref, accuracy))
        print(
            f'{kind.upper():3s}  ours {t_ours * 1e6:7.1f} us ({t_ours / t_sim:5.2f} sim steps)  '
            f'filterpy {t_ref * 1e6:8.1f} us  ({t_ref / t_ours:5.1f}x)  {accuracy}',
            flush=True,
        )
    lines = [
        f'Simulator sample step: {t_sim * 1e6:.1f} us.',
        '',
        '| filter | ours (us/sample) | in simulator steps | filterpy (us/sample) '
        '| filterpy / ours | share of one core at 5 kHz | accuracy |',
        '|---|---|---|---|---|---|---|',
    ]
    for kind, t_ours, t_ref, accuracy in rows:
        lines.append(
            f'| {kind.upper()} | {t_ours * 1e6:.1f} | {t_ours / t_sim:.2f} | {t_ref * 1e6:.1f} '
            f'| {t_ref / t_ours:.1f}x | {t_ours * 5000 * 100:.0f} % | {accuracy} |'
        )
    lines += [
        '',
        f'In the composed loop (``ControlLoop``: simulator + estimator + LQR), lockstep '
        f'({args.loop_seconds:g} s simulated) and real time ({args.realtime_seconds:g} s '
        "wall, 5 kHz); the estimator's share = its CPU per sample x 5,000/s:",
        '',
        '| filter | lockstep: estimator (us/sample) | lockstep: estimator share '
        '| lockstep: whole loop share | real time: estimator (us/sample) '
        '| real time: estimator share | real time: whole loop share | RTF | overruns |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for kind in ('kf', 'ekf', 'ukf'):
        t_est, t_loop = in_the_loop(model, linear, kind, args.loop_seconds)
        rt = in_real_time(kind, args.realtime_seconds)
        lost = '' if rt['held'] else ' (magnet lost)'
        lines.append(
            f'| {kind.upper()} | {t_est * 1e6:.1f} | {t_est * 5000 * 100:.0f} % '
            f'| {t_loop * 5000 * 100:.0f} % | {rt["estimator"] * 1e6:.1f} '
            f'| {rt["estimator"] * 5000 * 100:.0f} % | {rt["loop_share"] * 100:.0f} % '
            f'| {rt["rtf"]:.3f} | {rt["overruns"]}{lost} |'
        )
        if kind != 'kf':
            for where, t in (('lockstep', t_est), ('real time', rt['estimator'])):
                checks.append(
                    (
                        f'{kind.upper()} in the composed loop ({where}): estimator '
                        f'{t * 5000 * 100:.0f} % of a core at 5 kHz (< 50 %)',
                        t * 5000 < 0.5 and (where == 'lockstep' or rt['held']),
                    )
                )
    table = '\n'.join(lines)
    print()
    print(table)
    print()
    for text, ok in checks:
        print(f'{verdict(ok):8s}{text}')
    if args.markdown:
        with open(args.markdown, 'w') as f:
            f.write(table + '\n')
    return 0 if all(ok for _, ok in checks) else 1


if __name__ == '__main__':
    raise SystemExit(main())
