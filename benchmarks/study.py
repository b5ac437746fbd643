"""maglev-study: speed-up of 2 local workers over 1, and the overhead per run against the loop.

One run of this script measures, on V2 with the KF + LQR in the board's
set-up (each run from an x offset of 0.3 mm, a seed each):

* **the loop called directly**, the baseline: ``make_closed_loop`` once, then
  ``loop.simulator.seed = seed; loop.run(duration, x0=...)`` per run -- the
  cost of a ``--duration`` run;
* **the study around a run**: ``--short`` runs of one sample (0.2 ms), whose
  loop costs next to nothing, through the study (``run_study``: planning,
  the adapter and its cache, judging, the journal, the table) serially and on
  one Dask worker, minus the same runs called directly: what the study adds to
  each run, measured without the noise of long runs on a shared machine;
  the overhead per run is that over the direct run's cost;
* **the speed-up** of 2 local Dask workers over 1 on ``--runs`` runs (wall
  time; the CPU time per run, the workers' and this process's through
  ``Client.run``, shows whether the 2 workers did the same work). Each
  cluster is warmed first (every worker imports the package and builds the
  loop), so the timings are of the runs, not of the start-up. The machine is
  shared: the speed-up is bounded by the cores the others leave free, and the
  load average is printed.

Usage::

    python benchmarks/study.py                 # 12 runs of 1 s, 200 of one sample
    python benchmarks/study.py --runs 24 --short 500
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from maglev_ros.study import DaskBackend, SerialBackend, plan_runs, run_study, study_from_mapping
from maglev_ros.study.loop_adapter import simulate


def _spec(runs: int, duration: float, seed: int):
    return study_from_mapping(
        {
            'name': 'benchmark',
            'duration': duration,
            'seed': seed,
            'repeats': runs,
            'success': {'window': min(0.3, duration)},
            'fixed': {'params': 'maggy_v2', 'controller': 'lqr', 'x0.x': 0.3e-3},
        },
        'benchmark',
    )


_LOOP = []


@dataclass
class Timing:
    """Wall and CPU time of a batch of runs, s (CPU: this process and the workers)."""

    wall: float
    cpu: float


def _cpu(backend=None) -> float:
    """CPU time of this process, plus the workers' when given, s."""
    total = time.process_time()
    if backend is not None:
        total += sum(backend.client.run(time.process_time).values())
    return total


def _direct(spec) -> Timing:
    """Time the runs of ``spec`` on one loop built once (the first call builds it)."""
    from maglev_ros.control.closed_loop import make_closed_loop
    from maglev_ros.physics import linearize, make_model

    if not _LOOP:
        model = make_model('maggy_v2')
        _LOOP.append(make_closed_loop(model, linear=linearize(model)))
    loop = _LOOP[0]
    x0 = loop.simulator.model.hover_state(loop.z_eq)
    x0[0] += 0.3e-3
    tasks = plan_runs(spec)
    cpu, wall = time.process_time(), time.perf_counter()
    for task in tasks:
        loop.simulator.seed = task.seed
        loop.run(spec.duration, x0=x0)
    return Timing(time.perf_counter() - wall, time.process_time() - cpu)


def _study(spec, backend, out: Path, dask: bool = False) -> Timing:
    cpu, wall = _cpu(backend if dask else None), time.perf_counter()
    result = run_study(spec, out, backend)
    wall = time.perf_counter() - wall
    cpu = _cpu(backend if dask else None) - cpu
    assert result.complete
    return Timing(wall, cpu)


def _warm(backend, n: int) -> None:
    backend.wait_for_workers(n, timeout=120)
    backend.client.run(simulate, {'params': 'maggy_v2'}, 0, 0.01)


def _ms(t: Timing, n: int) -> str:
    return f'wall {t.wall / n * 1e3:.0f} ms/run, CPU {t.cpu / n * 1e3:.0f} ms/run'


def main(argv=None) -> int:
    """Measure and print the overhead per run and the 2-over-1 speed-up."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=12, help='runs of --duration')
    parser.add_argument('--short', type=int, default=200, help='runs of one sample')
    parser.add_argument('--duration', type=float, default=1.0, help='s per run')
    args = parser.parse_args(argv)
    n, k = args.runs, args.short
    tiny = 1.0 / 5000  # one sample: the run costs almost nothing, the machinery all
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        simulate({'params': 'maggy_v2'}, 0, 0.01)  # compile and build once
        _direct(_spec(1, 0.01, 0))
        run_study(_spec(2, tiny, 1), tmp / 'warm', SerialBackend())  # imports, first table
        direct = _direct(_spec(n, args.duration, 100))
        print(f'direct, {n} runs of {args.duration:g} s: {_ms(direct, n)}', flush=True)
        short_direct = _direct(_spec(k, tiny, 101))
        short_serial = _study(_spec(k, tiny, 101), SerialBackend(), tmp / 'short_serial')
        print(f'{k} runs of one sample: direct {_ms(short_direct, k)}', flush=True)
        print(f'{k} runs of one sample: serial study {_ms(short_serial, k)}', flush=True)
        timings = {}
        for workers in (1, 2):
            with DaskBackend(workers=workers) as backend:
                _warm(backend, workers)
                if workers == 1:
                    short_dask = _study(_spec(k, tiny, 101), backend, tmp / 'short_dask', True)
                    print(
                        f'{k} runs of one sample: 1 Dask worker {_ms(short_dask, k)}', flush=True
                    )
                timings[workers] = _study(
                    _spec(n, args.duration, 200), backend, tmp / f'dask{workers}', dask=True
                )
                loads.append(os.getloadavg()[0])
                print(
                    f'Dask, {workers} worker(s), {n} runs of {args.duration:g} s: '
                    f'{_ms(timings[workers], n)} (CPU: the workers and this process)',
                    flush=True,
                )
    per_run = direct.wall / n
    serial_cost = (short_serial.wall - short_direct.wall) / k
    dask_cost = (short_dask.wall - short_direct.wall) / k
    print(
        f'\nV2, KF + LQR; load average {min(loads):.1f}-{max(loads):.1f} during the run:'
        f'\n  a {args.duration:g} s run called directly: {per_run * 1e3:.0f} ms'
        f'\n  the study around a run (one-sample runs, study minus direct): serial '
        f'{serial_cost * 1e3:.2f} ms, 1 Dask worker {dask_cost * 1e3:.2f} ms'
        f'\n  overhead per {args.duration:g} s run: serial {100 * serial_cost / per_run:.2f} %, '
        f'Dask {100 * dask_cost / per_run:.2f} %'
        f'\n  speed-up of 2 local workers over 1: {timings[1].wall / timings[2].wall:.2f}x wall '
        f'(CPU per run with 2: {timings[2].cpu / timings[1].cpu:.2f}x that with 1)'
    )
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
