"""Where a study's runs are done: in this process, on local worker processes, or on a cluster.

The local and cluster back ends are Dask's (``distributed``): a
:class:`~distributed.LocalCluster` of one single-threaded worker process
per core (nothing to start by hand), or the workers of an existing
scheduler (``tcp://HOST:PORT``). Workers need only this package installed;
they import :func:`~maglev_ros.study.runner.run_task` themselves.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator
from typing import Any

__all__ = ['DaskBackend', 'SerialBackend', 'local_worker_count']


def local_worker_count() -> int:
    """Cores this process may use (the default number of local workers)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


@contextlib.contextmanager
def _workers_ignore_sigint():
    """Start worker processes with SIGINT ignored (they inherit it), then restore it.

    Ctrl-C in a terminal reaches every process of the group: this process
    stops the study (it cancels the runs and closes the cluster); the workers
    would each print a KeyboardInterrupt traceback.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


class SerialBackend:
    """Every run in this process, one after the other (debugging, baselines)."""

    workers = 1
    where = 'this process'

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        """Yield ``fn(task)`` for each task.

        Parameters
        ----------
        fn : callable
        tasks : iterable
        """
        for task in tasks:
            yield fn(task)

    def close(self) -> None:
        """Nothing to release."""

    def __enter__(self) -> SerialBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


class DaskBackend:
    """Runs on Dask workers: an embedded local cluster, or a scheduler's.

    Parameters
    ----------
    scheduler : str, optional
        ``tcp://HOST:PORT`` of a running scheduler; None starts a local
        cluster (closed with the back end).
    workers : int, optional
        Local worker processes (default: every core); not with ``scheduler``.
    timeout : float
        s to wait for the scheduler to answer.

    Raises
    ------
    OSError
        The scheduler cannot be reached (the message says which and what to do).
    """

    def __init__(
        self, scheduler: str | None = None, workers: int | None = None, timeout: float = 10.0
    ):
        from distributed import Client, LocalCluster

        self._cluster = None
        if scheduler is None:
            n = workers or local_worker_count()
            with warnings.catch_warnings(), _workers_ignore_sigint():
                # the scheduler's HTTP routes take another port when 8787 is busy: harmless
                warnings.filterwarnings('ignore', message='Port .* is already in use')
                self._cluster = LocalCluster(
                    n_workers=n,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                )
            self.client = Client(self._cluster)
            self.where = f'{n} local worker process{"es" if n > 1 else ""}'
        else:
            if workers is not None:
                raise ValueError('--workers is for the local cluster: a scheduler has its own')
            try:
                self.client = Client(scheduler, timeout=timeout)
            except (OSError, TimeoutError) as exc:
                raise OSError(
                    f'cannot reach the Dask scheduler {scheduler} ({exc}): start one with '
                    '`dask scheduler` and workers with `dask worker ADDRESS`'
                ) from None
            self.where = f'the Dask scheduler {scheduler}'
        self._futures: list = []

    @property
    def workers(self) -> int:
        """Worker threads the scheduler knows now."""
        info = self.client.scheduler_info()
        return sum(w.get('nthreads', 1) for w in info.get('workers', {}).values())

    def wait_for_workers(self, n: int = 1, timeout: float = 60.0) -> None:
        """Block until ``n`` workers are connected.

        Parameters
        ----------
        n : int
        timeout : float
            s.
        """
        self.client.wait_for_workers(n, timeout=timeout)

    def imap_unordered(self, fn: Callable[[Any], Any], tasks: Iterable[Any]) -> Iterator[Any]:
        """Submit ``fn(task)`` for every task; yield results as they finish.

        Parameters
        ----------
        fn : callable
            A module-level function (workers import it by name).
        tasks : iterable
        """
        from distributed import as_completed

        tasks = list(tasks)
        if not tasks:
            return
        self._futures = self.client.map(fn, tasks, pure=False)
        for future in as_completed(self._futures):
            yield future.result()
            future.release()

    def close(self) -> None:
        """Cancel what is pending, disconnect, and stop a local cluster."""
        try:
            if self._futures:
                self.client.cancel(self._futures)
        finally:
            self._futures = []
            self.client.close()
            if self._cluster is not None:
                self._cluster.close()

    def __enter__(self) -> DaskBackend:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
