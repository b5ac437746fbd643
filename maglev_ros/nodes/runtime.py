"""Running nodes: the executor, the spin loop, a background spinner, a node's ``main``."""

from __future__ import annotations

import os
import sys
import threading
import time

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.signals import SignalHandlerOptions

from maglev_ros.compile_watch import CompileWatch, compile_estimate, end_process
from maglev_ros.frozen_heap import frozen_heap
from maglev_ros.nodes.params import help_requested
from maglev_ros.nodes.scheduling import relax_event_threads
from maglev_ros.stop_signals import StopSignals

__all__ = ['Spinner', 'make_executor', 'run_nodes', 'spin']


def make_executor(context=None):
    """Return the fastest executor available: EventsExecutor, else SingleThreadedExecutor.

    Parameters
    ----------
    context : rclpy.context.Context, optional
        Its context (default: the default context).
    """
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:  # older rclpy
        from rclpy.executors import SingleThreadedExecutor

        return SingleThreadedExecutor(context=context)
    return EventsExecutor(context=context)


def spin(executor, context=None, stop=None, seconds=None, wait: float = 0.1) -> None:
    """Spin ``executor`` until its context shuts down, ``stop`` is set or ``seconds`` pass.

    Runs ``spin_once`` in a loop: the Jazzy EventsExecutor's own ``spin()``
    does not fire timers in the PyPI build, ``spin_once`` does.

    Parameters
    ----------
    executor : rclpy executor
        The executor (nodes added).
    context : rclpy.context.Context, optional
        Its context (default: the default context).
    stop : threading.Event, optional
        Set it to end the loop from another thread.
    seconds : float, optional
        Spin for at most this long, s (e.g. to run the callbacks already due
        after a stop: messages received before it).
    wait : float
        ``spin_once`` timeout, s.
    """
    context = context or rclpy.get_default_context()
    deadline = None if seconds is None else time.monotonic() + seconds
    while context.ok() and not (stop is not None and stop.is_set()):
        if deadline is not None and time.monotonic() >= deadline:
            break
        try:
            executor.spin_once(timeout_sec=wait)
        except ExternalShutdownException:
            break
        except Exception:  # noqa: BLE001 - re-raised unless the context is gone
            if context.ok():
                raise
            break  # a callback raced the shutdown (SIGINT/SIGTERM): nothing left to do


class Spinner:
    """Spin nodes on one executor in a background thread (tests, ``maglev-lab``).

    Parameters
    ----------
    context : rclpy.context.Context
        The nodes' context.
    nodes : sequence of Node
        Nodes to spin.
    """

    def __init__(self, context, nodes) -> None:
        import threading

        self.context = context
        relax_event_threads()
        self.executor = make_executor(context)
        for node in nodes:
            self.executor.add_node(node)
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=spin,
            args=(self.executor, context, self._stop),
            name='maglev-spinner',
            daemon=True,
        )
        self._thread.start()

    def add_node(self, node) -> None:
        """Add a node to the executor.

        Parameters
        ----------
        node : rclpy.node.Node
            The node.
        """
        self.executor.add_node(node)

    def close(self) -> None:
        """Stop spinning and shut the executor down (idempotent)."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._thread.join(timeout=10.0)
        self.executor.shutdown()


def run_nodes(
    factories,
    args: list[str] | None,
    name: str,
    errors: tuple,
    parameters=None,
    environment: dict[str, str] | None = None,
) -> int:
    """Init rclpy, build nodes, spin them on one executor until SIGINT/SIGTERM/SIGHUP.

    A second signal during the clean-up is ignored: the nodes are destroyed
    (bags finalised, coils zeroed) before the context shuts down, and the
    exit status stays 0.

    Parameters
    ----------
    factories : sequence of callable
        Each returns a node (called after ``rclpy.init``).
    args : list of str or None
        Command-line arguments (ROS arguments included; None: ``sys.argv``).
    name : str
        Logger name for parameter errors.
    errors : tuple of exception types
        Parameter errors: logged in one line, exit status 2.
    parameters : maglev_ros.parameters.ParameterTable, optional
        The node's parameters: ``--help`` (``-h``) before ``--ros-args``
        prints them and returns 0 without starting ROS.
    environment : dict, optional
        Environment variables the nodes want before ROS starts (e.g. the
        middleware's publication mode); a variable already set is kept.

    Returns
    -------
    int
        0, or 2 for invalid parameters or ROS arguments.
    """
    if parameters is not None and help_requested(args):
        argv = sys.argv if args is None else args
        prog = (
            os.path.splitext(os.path.basename(argv[0]))[0]
            if argv and not argv[0].startswith('-')
            else None
        )
        print(parameters.help_text(prog), end='')
        return 0
    for variable, value in (environment or {}).items():
        os.environ.setdefault(variable, value)
    # SIGINT, SIGTERM and SIGHUP end the spin; one arriving during the clean-up
    # (launch's own SIGINT after a terminal's Ctrl-C) no longer interrupts it:
    # rclpy's handlers are off, so the context stays valid until the nodes are
    # destroyed (bags finalised, coils zeroed) and is shut down last
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except Exception as err:  # noqa: BLE001 - rcl refuses the command line (RCLError)
        text = str(err).strip().splitlines()
        print(f'{name}: error: {text[0] if text else type(err).__name__}', file=sys.stderr)
        return 2
    nodes = []
    executor = None
    # the clean-up runs once: here, or in CompileWatch's on_abort (the other caller
    # waits for it to finish)
    cleaning = threading.Lock()
    cleaned = []

    def clean_up() -> None:
        with cleaning:
            if cleaned:
                return
            cleaned.append(True)
            if executor is not None:
                executor.shutdown()
            for node in reversed(nodes):
                node.destroy_node()
            rclpy.try_shutdown()

    # a stop signal during a first run's kernel compile ends it within about 1 s
    watch = CompileWatch(name, compile_estimate(name), on_abort=clean_up)
    with StopSignals() as stop, watch:
        try:
            for factory in factories:
                nodes.append(factory())
            relax_event_threads()  # DDS timer wake-ups must not preempt the publishers
            executor = make_executor()
            for node in nodes:
                executor.add_node(node)
            # the built nodes' objects out of the collector's way: a full collection
            # of them stalls the callbacks for 45-270 ms (maglev_ros.frozen_heap)
            with frozen_heap():
                spin(executor, stop=stop.event)
                spin(executor, seconds=0.1, wait=0.01)  # what arrived before the signal
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except errors as err:
            rclpy.logging.get_logger(name).error(str(err))
            return 2
        except Exception:
            if not watch.interrupted:  # else numba's own error after the stop: a stop
                raise
        finally:
            clean_up()
    if stop.requested:  # cleaned up; the interpreter's teardown would take 1-3 s more
        end_process(0)
    return 0
