"""maglev_ros.cdr: CDR bytes of ROS 2 messages, without rclpy.

One place knows where fields sit in a serialised message, for decoding bags
and for publishing raw bytes:

* ``layout``: the CDR walker (:func:`cdr_layout`) and the strided decoder of
  many equal-layout messages (:func:`decode_columns`), used by
  :mod:`maglev_ros.bags`;
* ``templates``: a message serialised once with the offsets of its stamp and
  varying float64s (:class:`RawLayout`), and the layouts of the Maggy
  graph's 5 kHz messages (:func:`field_layout`, :func:`currents_layout`,
  :func:`odometry_layout`, :func:`estimate_layout`, :func:`clock_layout`);
* ``batch``: a burst of samples' messages written in one compiled call
  (:class:`~maglev_ros.cdr.batch.SampleSerialiser`), used by the simulator
  and driver nodes. Not re-exported here: it imports numba, which nodes that
  publish no bursts need not load.
* ``typestore``: ROS 2 Jazzy's message definitions (:func:`jazzy_typestore`).
"""

from .layout import CdrLayout, Path, cdr_layout, decode_columns
from .templates import (
    CURRENT_VALUES,
    ESTIMATE_VALUES,
    FIELD_VALUES,
    HEADER_STAMP,
    ODOMETRY_VALUES,
    RawLayout,
    clock_layout,
    currents_layout,
    default_message,
    estimate_layout,
    field_layout,
    odometry_layout,
    raw_layout,
)
from .typestore import jazzy_typestore

__all__ = [
    'CURRENT_VALUES',
    'FIELD_VALUES',
    'HEADER_STAMP',
    'ESTIMATE_VALUES',
    'ODOMETRY_VALUES',
    'CdrLayout',
    'Path',
    'RawLayout',
    'cdr_layout',
    'clock_layout',
    'currents_layout',
    'decode_columns',
    'default_message',
    'field_layout',
    'jazzy_typestore',
    'estimate_layout',
    'odometry_layout',
    'raw_layout',
]
