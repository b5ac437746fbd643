"""maglev-study: speed-up of 2 local workers over 1, and the overhead per run against the loop.

One run of this script measures, on the same runs (V2, KF + LQR, the board's
set-up, 1 s each, x offset 0.3 mm, a seed each):

* **direct**: the baseline, the closed loop called by hand --
  :func:`~maglev_ros.control.closed_loop.make_closed_loop` once, then for each
  seed ``loop.simulator.seed = seed; loop.run(1.0, x0=...)`` -- in this process;
* **serial study**: the same runs through the study machinery in this process
  (``run_study`` on the serial back end: planning, the loop adapter and its
  cache, judging, the journal, the table);
* **Dask, 1 worker** and **Dask, 2 workers**: the same runs on an embedded
  local cluster (what ``maglev-study`` does by default), each cluster warmed
  first (every worker imports the package and builds the loop once), so the
  timings are of the runs, not of the start-up.

Direct and serial are interleaved over ``--rounds`` rounds, in alternating
order, and compared per round (the median ratio is printed), so a change in
the others' load hits both; both reuse one loop built before the timing.
Printed: the overhead per run of the serial study and of the 1-worker
cluster against direct, and the speed-up of 2 workers over 1. The machine
is shared: the speed-up is bounded by the cores the others leave free.

Usage::

    python benchmarks/study.py                 # 12 runs of 1 s, 4 rounds
    python benchmarks/study.py --runs 24 --duration 1.0 --rounds 2
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
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


def _direct(spec) -> float:
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
    start = time.perf_counter()
    for task in tasks:
        loop.simulator.seed = task.seed
        loop.run(spec.duration, x0=x0)
    return time.perf_counter() - start


def _study(spec, backend, out: Path) -> float:
    start = time.perf_counter()
    result = run_study(spec, out, backend)
    elapsed = time.perf_counter() - start
    assert result.complete
    return elapsed


def _warm(backend, n: int) -> None:
    backend.wait_for_workers(n, timeout=120)
    backend.client.run(simulate, {'params': 'maggy_v2'}, 0, 0.01)


def main(argv=None) -> int:
    """Measure and print the overhead per run and the 2-over-1 speed-up."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--runs', type=int, default=12)
    parser.add_argument('--duration', type=float, default=1.0, help='s per run')
    parser.add_argument('--rounds', type=int, default=4)
    args = parser.parse_args(argv)
    n = args.runs
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        simulate({'params': 'maggy_v2'}, 0, 0.01)  # compile and build once
        _direct(_spec(1, 0.01, 0))
        ratios = []
        for r in range(args.rounds):
            spec = _spec(n, args.duration, 100 + r)
            if r % 2:  # alternate the order: a change of the others' load hits both
                serial = _study(spec, SerialBackend(), tmp / f'serial{r}')
                direct = _direct(spec)
            else:
                direct = _direct(spec)
                serial = _study(spec, SerialBackend(), tmp / f'serial{r}')
            ratios.append(serial / direct)
            print(
                f'round {r}: direct {direct / n * 1e3:.0f} ms/run, serial study '
                f'{serial / n * 1e3:.0f} ms/run (x{serial / direct:.3f})',
                flush=True,
            )
        timings = {}
        for workers in (1, 2):
            with DaskBackend(workers=workers) as backend:
                _warm(backend, workers)
                spec = _spec(n, args.duration, 200)
                direct = _direct(spec)
                timings[workers] = _study(spec, backend, tmp / f'dask{workers}')
                print(
                    f'Dask, {workers} worker(s): {timings[workers] / n * 1e3:.0f} ms/run '
                    f'(direct in this process just before: {direct / n * 1e3:.0f} ms/run)',
                    flush=True,
                )
                if workers == 1:
                    dask_ratio = timings[1] / direct
    ratio = statistics.median(ratios)
    print(f'\n{n} runs of {args.duration:g} s (V2, KF + LQR):')
    print(
        f'  overhead per run, serial study against the loop called directly: '
        f'{100 * (ratio - 1):+.1f} % (median of {args.rounds} rounds)'
    )
    print(
        f'  overhead per run, 1 Dask worker against the loop called directly: '
        f'{100 * (dask_ratio - 1):+.1f} %'
    )
    print(f'  speed-up of 2 local workers over 1: {timings[1] / timings[2]:.2f}x')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
