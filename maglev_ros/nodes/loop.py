"""Loop node: ``ros2 run maglev_ros loop``, the closed loop composed in one process.

The controller-manager shape: one node hosts the hot path (sample, estimate,
command) as direct calls through the ROS-free
:class:`~maglev_ros.loop.ControlLoop`, in a thread of its own paced by the
plant, and publishes the topics of ``docs/topics.md`` for observers (a
recorder, RViz, ``ros2 topic echo``) from a broadcaster thread that never
holds the loop up: by default the newest sample of each control period
(``control_rate``, 1 kHz), every sample with ``publish_every_sample``.

Plant: the simulator in real time (``plant: simulator``), with its noise,
quantisation, sensor delay and coil dynamics, and optionally a magnet other
than the believed one (``plant_polarization``, ``plant_mass``); or a V2x board
(``plant: board``, ``port``), whose 5 kHz stream paces the loop and whose
coils are left at zero current when the node stops or the link fails.

Start: at once, or, with ``start_reader`` (a recorder's node name), once that
node reads ``start_reader_topics``. The bag then holds the first sample, and
the loop does not start while the recorder's process is still coming up and
taking the CPU (a simulated magnet is lost when its loop is starved in its
first tenths of a second).

Diagnostics: real-time factor, overruns, samples dropped by the broadcaster,
the controller's level; ERROR once the magnet is lost (the loop then stops).
"""

from __future__ import annotations

import sys
import threading
from contextlib import ExitStack

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node

from maglev_ros.estimation.config import FILTERS
from maglev_ros.frozen_heap import frozen_heap
from maglev_ros.hardware.serial_link import LinkError
from maglev_ros.loop import SimulatedLoopSettings
from maglev_ros.loop.simulated_setup import build_loop, plant_health
from maglev_ros.nodes.broadcast import LoopBroadcaster
from maglev_ros.nodes.messages import diagnostic_array
from maglev_ros.nodes.params import (
    NodeParameterError,
    Param,
    ParameterTable,
    choice,
    integer,
    node_name,
    topic_names,
)
from maglev_ros.nodes.params import number as num
from maglev_ros.nodes.qos import DIAGNOSTICS_QOS
from maglev_ros.nodes.runtime import run_nodes
from maglev_ros.nodes.start_gate import reads_topics
from maglev_ros.topics import COMMAND_TOPIC, DIAGNOSTICS_TOPIC, ESTIMATE_TOPIC

__all__ = ['PARAMETERS', 'LoopNode', 'LoopParameterError', 'main']

NODE_NAME = 'maglev_loop'
PLANTS = ('simulator', 'board')
FIRMWARES = ('v2x', 'v4x', 'v4x_pc')  # the driver's; the composed loop runs v2x
SWITCH_INTERVAL_S = 0.0005  # s: the loop's thread gets the GIL back within this
START_POLL_S = 0.02  # s between looks at the graph while the loop waits for its reader


class LoopParameterError(NodeParameterError):
    """A loop parameter has an invalid value."""


PARAMETERS = ParameterTable(
    NODE_NAME,
    LoopParameterError,
    {
        'plant': Param(
            'simulator', 'the plant: simulator (real time) or board', check=choice(*PLANTS)
        ),
        'port': Param('/dev/ttyACM0', 'board: serial device'),
        'firmware': Param(
            'v2x',
            'board: its firmware; the composed loop commands a V2x board (a V4x PC-control '
            'board: maglev-lab --firmware v4x_pc)',
            check=choice(*FIRMWARES),
        ),
        'n_sensors': Param(3, 'board: sensors per record', check=integer(1)),
        'command_timeout': Param(
            0.1, 'board: s without a command before the coils go to zero', check=num(0, above=True)
        ),
        'params': Param('maggy_v2', 'parameter set believed: maggy_v2, maggy_v4 or a YAML path'),
        'sample_rate': Param(5000.0, 'samples per second, Hz', check=num(0, above=True)),
        'control_rate': Param(
            1000.0, 'commands per second, Hz (divides sample_rate)', check=num(0, above=True)
        ),
        'filter': Param('kf', 'estimator: kf, ekf or ukf', check=choice(*FILTERS)),
        'mode': Param('lqr', 'controller: lqr or pd', check=choice('lqr', 'pd')),
        'command_delay': Param(0, 'control periods before a command applies', check=integer(0)),
        'sensor_noise': Param(1.0e-4, 'sensor noise, T rms per axis', check=num(0)),
        'sensor_quantization': Param(0.098e-3, 'sensor resolution, T per LSB', check=num(0)),
        'sensor_delay': Param(1, 'sensor delay, samples', check=integer(0)),
        'coil_dynamics': Param(True, 'coil L/R lag in the plant'),
        'seed': Param(0, 'sensor-noise seed', check=integer(0)),
        'plant_polarization': Param(
            1.0, "plant magnet's polarisation / the believed one's", check=num(0, above=True)
        ),
        'plant_mass': Param(
            1.0, "plant magnet's mass / the believed one's", check=num(0, above=True)
        ),
        'publish_every_sample': Param(
            False, 'publish every sample (else the newest of each control period)'
        ),
        'diagnostics_period': Param(1.0, 's between diagnostics', check=num(0, above=True)),
        'start_reader': Param(
            '',
            'a node (a recorder) that must read the start_reader_topics before the loop '
            "starts; '': start at once",
            check=node_name(),
        ),
        'start_reader_topics': Param(
            [COMMAND_TOPIC, ESTIMATE_TOPIC],
            'topics the start_reader must read',
            check=topic_names(),
        ),
    },
)


class LoopNode(Node):
    """The composed closed loop (see the module docstring).

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.node.Node``.

    Raises
    ------
    LoopParameterError
        If a parameter is invalid or the loop cannot be built from them.
    """

    def __init__(self, **kwargs) -> None:
        super().__init__(NODE_NAME, **kwargs)
        values = PARAMETERS.validate(PARAMETERS.declare(self))
        self.publish_every_sample = values.pop('publish_every_sample')
        period = values.pop('diagnostics_period')
        reader = values.pop('start_reader')
        topics = tuple(self.resolve_topic_name(t) for t in values.pop('start_reader_topics'))
        plant = values.pop('plant')
        firmware = values.pop('firmware')
        if plant == 'board' and firmware != 'v2x':
            raise LoopParameterError(
                f'{NODE_NAME}: firmware {firmware!r}: the composed loop commands a V2x board; '
                'run a V4x PC-control board with maglev-lab --firmware v4x_pc --board PORT '
                '(docs/boards.md)'
            )
        board = {k: values.pop(k) for k in ('port', 'n_sensors', 'command_timeout')}
        self.settings = s = SimulatedLoopSettings(**values)
        try:
            self.loop, self.plant = build_loop(s, board if plant == 'board' else None)
        except (ValueError, OSError, LinkError) as err:
            raise LoopParameterError(f'{NODE_NAME}: {err}') from err
        simulator = getattr(self.plant, 'simulator', None)
        sensors = self.plant.n_sensors if simulator is None else simulator.model.n_outputs // 3
        self.broadcaster = LoopBroadcaster(self, sensors, true_state=simulator is not None)
        every_sample = self.publish_every_sample
        send = self.broadcaster
        self.loop.observers.add(send if every_sample else lambda x: x.command is None or send(x))
        self._diag_pub = self.create_publisher(DiagnosticArray, DIAGNOSTICS_TOPIC, DIAGNOSTICS_QOS)
        self.create_timer(period, self.publish_diagnostics)
        self._stop = threading.Event()
        self._switch = sys.getswitchinterval()
        sys.setswitchinterval(SWITCH_INTERVAL_S)
        self._thread = threading.Thread(target=self._run, name='maglev-loop', daemon=True)
        # the full collection before the loop runs, not during it (until destroy_node)
        self._heap = ExitStack()
        self._heap.enter_context(frozen_heap())
        where = f'the board on {board["port"]}' if plant == 'board' else 'the simulator'
        wait = f'; starts once {reader} reads {", ".join(topics)}' if reader else ''
        self.get_logger().info(
            f'{s.params}: {s.filter if s.mode == "lqr" else "no estimator"} + {s.mode} at '
            f'{s.control_rate:g} Hz on {where} at {s.sample_rate:g} Hz (real time), '
            f'noise {s.sensor_noise:g} T, plant polarisation x{s.plant_polarization:g}, '
            f'mass x{s.plant_mass:g}; publishing '
            f'{"every sample" if every_sample else f"at {s.control_rate:g} Hz"}{wait}'
        )
        self._gate = None
        if reader:
            self._gate = self.create_timer(START_POLL_S, lambda: self._start_when(reader, topics))
        else:
            self._thread.start()

    def _start_when(self, reader: str, topics: tuple[str, ...]) -> None:
        if not self.started and reads_topics(self, reader, topics):
            self.destroy_timer(self._gate)
            self._thread.start()
            self.get_logger().info(f'{reader} reads; the loop starts')

    @property
    def started(self) -> bool:
        """Whether the loop's thread started (see ``start_reader``)."""
        return self._thread.ident is not None

    def _run(self) -> None:
        self.loop.run(sys.maxsize, stop=self._stop.is_set)
        if self.loop.stopped and self.context.ok():
            self.get_logger().error(f'magnet lost: {self.loop.reason}; the loop stopped')

    @property
    def status(self) -> tuple[int, str, dict]:
        """Diagnostic level (0 OK, 1 WARN, 2 ERROR), message and values."""
        level, message = (2, f'magnet lost: {self.loop.reason}') if self.loop.stopped else (0, '')
        if not self.started:
            message = 'waiting for the start_reader to read its topics'
        if not level and self.broadcaster.error is not None:
            level, message = 2, f'publishing failed: {self.broadcaster.error!r}'
        plant = self.plant
        if not level and getattr(plant, 'overruns', 0):
            level, message = 1, 'the loop fell behind the plant (overruns)'
        values = plant_health(plant)
        values.update(
            broadcast_dropped=self.broadcaster.dropped,
            broadcast_published=self.broadcaster.published,
            controller=self.loop.controller.status().level,
        )
        return level, message or 'levitating', values

    def publish_diagnostics(self) -> None:
        """Publish the loop's health on ``/diagnostics``."""
        level, message, values = self.status
        self._diag_pub.publish(
            diagnostic_array(
                self.get_clock().now().nanoseconds, f'{NODE_NAME}: loop', level, message, values
            )
        )

    def destroy_node(self) -> None:
        """Stop the loop, then the broadcaster (what it holds is published first)."""
        self._stop.set()
        if self.started:
            self._thread.join(timeout=5.0)
        self._heap.close()
        self.plant.close()  # a board's coils at zero current
        self.broadcaster.close()
        sys.setswitchinterval(self._switch)
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the composed loop until SIGINT or SIGTERM.

    Parameters
    ----------
    args : list of str, optional
        Command-line arguments (ROS arguments included).

    Returns
    -------
    int
        Exit status: 0, or 2 for invalid parameters.
    """
    return run_nodes([LoopNode], args, NODE_NAME, (LoopParameterError,), PARAMETERS)


if __name__ == '__main__':
    raise SystemExit(main())
