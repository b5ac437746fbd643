"""QoS profiles of the Maggy graph (``docs/topics.md``), chosen per kind of stream.

QoS (as the driver's docstring states it):

* sensor streams (fields, currents, true state, ``/clock``): RELIABLE,
  KEEP_LAST 1000 - every sample must arrive for identification; 1000 samples
  are 0.2 s at 5 kHz;
* commands (real time): BEST_EFFORT, KEEP_LAST 10 - matches both reliable and
  best-effort publishers; a stale command is worth nothing;
* commands (lockstep simulation): RELIABLE, KEEP_LAST 1000 - every command
  drives exactly one sample, so none may be lost (a reliable publisher, as
  the excitation node's, is then required);
* the newest input only (the real-time controller's estimates): BEST_EFFORT,
  KEEP_LAST 1 - it answers the newest estimate; older ones queued behind a
  stall would only be answered late (a recorder still takes every one);
* markers: RELIABLE, KEEP_LAST 1 (RViz's default); diagnostics: KEEP_LAST 10.

A subscriber works with either publisher choice: a best-effort subscription
matches reliable and best-effort publishers.
"""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

__all__ = ['COMMAND_QOS', 'DIAGNOSTICS_QOS', 'LATEST_QOS', 'LOCKSTEP_COMMAND_QOS', 'MARKERS_QOS']
__all__ += ['SENSOR_QOS']

SENSOR_QOS = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
COMMAND_QOS = QoSProfile(
    depth=10, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST
)
LOCKSTEP_COMMAND_QOS = QoSProfile(
    depth=1000, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
)
LATEST_QOS = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST
)
MARKERS_QOS = QoSProfile(
    depth=1,
    reliability=ReliabilityPolicy.RELIABLE,
    history=HistoryPolicy.KEEP_LAST,
    durability=DurabilityPolicy.VOLATILE,
)
DIAGNOSTICS_QOS = QoSProfile(depth=10)
