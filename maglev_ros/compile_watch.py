"""The first run's kernel compile: say so, and stop promptly when asked to.

numba compiles a kernel on its first call and caches the machine code
(``cache=True``), so only the first run after an install (or after the
package's sources change) compiles: 10 to 50 s on a 2-core machine, more under
load. :class:`CompileWatch` listens to numba's ``numba:compile`` event
(sent on a cache miss only) and

* prints one line when the first compile starts: ``compiling kernels, first
  run only: ~N s (cache: DIR)``;
* makes a stop signal (SIGINT, SIGTERM, SIGHUP) end a compile within about a
  second. Python runs its signal handlers between bytecodes of the main
  thread, and a compile spends up to 5 s at a time inside LLVM (C code), so a
  handler alone may come too late. Instead the C-level wake-up fd
  (:func:`signal.set_wakeup_fd`) wakes a watcher thread at once; during a
  compile it raises :class:`CompileInterrupted` (a ``KeyboardInterrupt``) in
  the main thread, which takes effect at the main thread's next bytecode, and
  if the compile is still running ``grace`` s later it calls ``on_abort``
  (the caller's clean-up: bags finalised, coils zeroed) and ends the process
  with status ``128 + signal``. After a stop signal no compile starts (one
  would raise :class:`CompileInterrupted`), so a signal that falls between two
  compiles does not leave the process compiling the rest.

:func:`end_process` ends a stopped process after its clean-up without the
interpreter's teardown (1 to 3 s under load), for the same 2 s.

Where the cache lives is numba's choice, in this order: ``NUMBA_CACHE_DIR``
if set; ``__pycache__`` beside each module if that directory is writable (a pip
venv, a colcon install tree, a source checkout); else the user's cache
directory (``~/.cache/numba``, for a read-only site-packages). Pure Python, no ROS.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import TextIO

__all__ = [
    'CompileInterrupted',
    'CompileWatch',
    'PROGRESS_TEXT',
    'compile_estimate',
    'end_process',
]

PROGRESS_TEXT = 'compiling kernels, first run only'
# s, the first run's compile on a 2-core machine at load 1 (numba 0.68), by program
_ESTIMATES_S = {'maglev-lab': 45.0}
_DEFAULT_ESTIMATE_S = 20.0  # a node or another tool


def compile_estimate(prog: str) -> float:
    """Return the expected first-run compile time of a program now, s (progress line).

    The time on an idle 2-core machine, scaled by the machine's load: the
    compile is CPU-bound, so at a load of 12 on 2 cores it takes about 6 times
    as long.

    Parameters
    ----------
    prog : str
        Program (or node) name.
    """
    try:
        busy = os.getloadavg()[0] / (os.cpu_count() or 1)
    except OSError:  # no load average on this platform
        busy = 1.0
    return _ESTIMATES_S.get(prog, _DEFAULT_ESTIMATE_S) * max(1.0, busy)


_STOP_SIGNALS = frozenset({int(signal.SIGINT), int(signal.SIGTERM), int(signal.SIGHUP)})


def _compiler_busy() -> bool:
    """Whether a thread holds numba's compiler lock (compiling or loading a kernel)."""
    from numba.core.compiler_lock import global_compiler_lock

    lock = global_compiler_lock._lock
    if lock.acquire(blocking=False):
        lock.release()
        return False
    return True


def end_process(status: int) -> None:
    """End the process now, after its clean-up, without the interpreter's teardown.

    Flushes stdout, stderr and the logging handlers, then ``os._exit``: the
    teardown (garbage-collecting numba's and rclpy's objects, 1 to 3 s on a
    loaded 2-core machine) is skipped, so a stopped process ends within 2 s of
    the signal. Only for a process whose clean-up has run.

    Parameters
    ----------
    status : int
        Exit status.
    """
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)


class CompileInterrupted(KeyboardInterrupt):
    """A stop signal arrived while numba compiled a kernel."""


def _listener(watch: CompileWatch):
    """Return a numba event listener calling the watch (numba imported now, not earlier)."""
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev: event.Event) -> None:
            watch._started(ev.data.get('dispatcher'))

        def on_end(self, ev: event.Event) -> None:
            watch._ended()

    return _Listener()


class CompileWatch:
    """Announce numba compiles and end them on a stop signal (a context manager).

    Enter it in the main thread, after the process's signal handlers are
    installed (the handlers stay; the wake-up fd only adds a prompt watcher).
    Outside the main thread only the progress line works.

    Parameters
    ----------
    prog : str
        Program name starting the progress line.
    estimate_s : float
        Typical compile time of this program on a 2-core machine, s
        (printed as ``~N s``).
    stream : text stream, optional
        Where the line goes (default ``sys.stderr``).
    grace : float, optional
        s the main thread has, after a signal during a compile, to leave it
        before ``on_abort`` runs and the process ends.
    on_abort : callable, optional
        Clean-up run (in the watcher thread) before such an exit; it must be
        safe while the main thread is stopped inside the compile.

    Attributes
    ----------
    compiles : int
        Compiles seen (nested ones included).
    """

    def __init__(
        self,
        prog: str,
        estimate_s: float,
        stream: TextIO | None = None,
        grace: float = 0.8,
        on_abort: Callable[[], None] | None = None,
    ) -> None:
        self.prog = prog
        self.estimate_s = float(estimate_s)
        self.stream = stream
        self.grace = float(grace)
        self.on_abort = on_abort
        self.compiles = 0
        self._depth = 0
        self._announced = False
        self._listener = None
        self._fds: tuple[int, int] | None = None
        self._previous_fd = -1
        self._thread: threading.Thread | None = None
        self._main_id = threading.main_thread().ident
        self._stop_signum: int | None = None
        self._cut = False  # a compile was stopped (or refused) for a stop signal

    @property
    def stop_signal(self) -> int | None:
        """The first stop signal the watcher saw, or None."""
        return self._stop_signum

    @property
    def interrupted(self) -> bool:
        """Whether a compile was stopped, or refused to start, for a stop signal."""
        return self._cut

    def end_if_interrupted(self, status: int) -> None:
        """End the process now with ``status`` if a stop signal cut a compile.

        Call it after the clean-up (bags finalised, coils zeroed); see
        :func:`end_process`.

        Parameters
        ----------
        status : int
            Exit status.
        """
        if self.interrupted:
            end_process(status)

    @property
    def compiling(self) -> bool:
        """Whether a compile is running now."""
        return self._depth > 0

    def __enter__(self) -> CompileWatch:
        from numba.core import event  # here: a process that never compiles imports it late

        self._listener = _listener(self)
        event.register('numba:compile', self._listener)
        if threading.current_thread() is threading.main_thread():
            read_fd, write_fd = os.pipe()
            os.set_blocking(write_fd, False)
            try:
                self._previous_fd = signal.set_wakeup_fd(write_fd, warn_on_full_buffer=False)
            except ValueError:  # not supported here: the progress line only
                os.close(read_fd)
                os.close(write_fd)
                return self
            self._fds = (read_fd, write_fd)
            self._thread = threading.Thread(
                target=self._watch, args=(read_fd,), name='maglev-compile-watch', daemon=True
            )
            self._thread.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        from numba.core import event

        event.unregister('numba:compile', self._listener)
        if self._fds is not None:
            signal.set_wakeup_fd(self._previous_fd)
            read_fd, write_fd = self._fds
            self._fds = None
            os.close(write_fd)  # the watcher's read ends (EOF)
            if self._thread is not None:
                self._thread.join(timeout=1.0)
            os.close(read_fd)

    # -- numba's events -----------------------------------------------------------

    def _started(self, dispatcher) -> None:
        if self._stop_signum is not None:  # no new compile once a stop signal came
            self._cut = True
            raise CompileInterrupted(f'signal {self._stop_signum} during the kernel compile')
        self.compiles += 1
        self._depth += 1
        if not self._announced:
            self._announced = True
            where = getattr(getattr(dispatcher, '_cache', None), '_cache_path', None)
            cache = f' (cache: {where or "none"})'
            print(
                f'{self.prog}: {PROGRESS_TEXT}: ~{self.estimate_s:.0f} s{cache}',
                file=self.stream or sys.stderr,
                flush=True,
            )

    def _ended(self) -> None:
        self._depth = max(0, self._depth - 1)

    # -- the watcher -----------------------------------------------------------------

    def _watch(self, read_fd: int) -> None:
        while True:
            try:
                data = os.read(read_fd, 64)
            except OSError:
                return
            if not data:
                return
            stops = [s for s in data if s in _STOP_SIGNALS]
            if stops and self._stop_signum is None:
                # from now on no compile starts (_started raises); one running is ended
                self._stop_signum = stops[0]
                if self.compiling:
                    self._interrupt(stops[0])

    def _interrupt(self, signum: int) -> None:
        self._cut = True
        deadline = time.monotonic() + self.grace
        while self.compiling and _compiler_busy():
            if time.monotonic() >= deadline:
                break
            # again until the compile ends: one that lands in a ctypes callback
            # (LLVM calls back into numba) is printed and dropped there
            if self._main_id is not None:
                ctypes.pythonapi.PyThreadState_SetAsyncExc(
                    ctypes.c_ulong(self._main_id), ctypes.py_object(CompileInterrupted)
                )
            time.sleep(0.05)
        else:
            return  # the main thread left the compile: its clean-up runs there
        try:
            if self.on_abort is not None:
                self.on_abort()
        finally:
            print(
                f'{self.prog}: stopped during the kernel compile '
                f'({signal.Signals(signum).name}); the next run compiles again',
                file=self.stream or sys.stderr,
                flush=True,
            )
            os._exit(128 + signum)
