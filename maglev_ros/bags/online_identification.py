"""Online identification of live messages: the ROS-free core of the identifier node.

One object that takes each message as it arrives and keeps a recursive ARX
(:class:`~maglev_ros.bags.live.ChannelIdentifier` around
:class:`~maglev_ros.sysid.online.OnlineArx`) of the channels written in the bag
converter's syntax (``TOPIC:PATH`` and linear combinations, see
:mod:`~maglev_ros.bags.channels`):

* **channels**: parsed, and each command current resolved for the message type
  of its topic (``data[i]`` of an old spec reads ``effort[i]`` of a JointState
  command: :mod:`~maglev_ros.bags.command_fields`);
* **sample completeness**: a sample is complete when every *sample* topic the
  channels read (messages with a header: fields, currents, states) has
  delivered its message of one stamp (:class:`~maglev_ros.bags.live.StampAligner`),
  then evaluated with the trigger topic last. The commands and the excitation
  are inputs held at their latest value (zero-order hold), as the bag
  converter holds them. Stamped (``sensor_msgs/JointState``, stamped with the
  sample they answer), a sample waits until each has a message stamped at or
  after it, and its input is the newest stamped at or before it: the
  converter's pairing, exact whatever the order of arrival across topics; a
  trigger naming a command topic then gives way to the sample's own topics.
  Header-less (``std_msgs/Float64MultiArray`` of older publishers), they are
  taken as they arrive; if the trigger is one, every trigger message completes
  a sample, and ``complete_on_next`` holds a completed sample until the next
  stamp's first message, so a command that answers it (a real-time burst's)
  is its input;
* **window**: samples whose stamp is before ``identify_from`` or after
  ``identify_until`` are counted and left out, their values still held;
* **report**: the coefficients, the prediction error and fit, and the
  diagnostics values, for a caller to publish.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ..parameters import NodeParameterError, check_settings, integer, number, setting
from ..sysid.online import CoefficientLayout, IdentifierStatus
from ..topics import (
    FIELD_MESSAGE_TYPE,
    MESSAGE_TYPES,
    current_channel,
    field_channel,
    field_topic,
)
from .channels import parse_channel
from .command_fields import COMMAND_TOPICS, resolve_channel
from .errors import BagError
from .live import ChannelIdentifier, StampAligner
from .names import normalize_topic
from .typestore import jazzy_typestore

__all__ = [
    'IdentificationConfigError',
    'IdentificationReport',
    'OnlineIdentification',
    'OnlineIdentificationConfig',
    'message_type_of',
]

_FIELD_TOPIC = re.compile('^' + re.escape(field_topic(0)).replace('0', r'\d+') + '$')
OK, ERROR = 0, 2  # diagnostic levels (diagnostic_msgs/DiagnosticStatus)


class IdentificationConfigError(BagError, ValueError):
    """A setting of :class:`OnlineIdentificationConfig` is invalid."""


def _channels(name: str, specs: tuple[str, ...]) -> tuple[str, ...]:
    if not specs or any(not s.strip() for s in specs):
        raise NodeParameterError(
            f'{name} must be a non-empty list of channel specs TOPIC:FIELD, got {list(specs)}'
        )
    return specs


def _orders(name: str, values: tuple[int, ...]) -> tuple[int, ...]:
    if not values or any(v < 0 for v in values):
        raise NodeParameterError(
            f'{name} must be a non-empty list of integers >= 0, got {list(values)}'
        )
    return values


_INPUT_UX = f'ux=0.5*{current_channel(0)}-0.5*{current_channel(1)}'


@dataclass(frozen=True)
class OnlineIdentificationConfig:
    """What to identify and how (the identifier node's validated parameters).

    Attributes
    ----------
    outputs, inputs : tuple of str
        Channel specs (the bag converter's syntax).
    na : tuple of int
        One order for all, or ny*ny values row by row.
    nb, nk : tuple of int
        One value for all, or ny*nu values row by row (samples).
    forgetting : float
        Forgetting factor in (0, 1].
    initial_covariance : float
        ``p0`` of ``P0 = p0 I``.
    window : int
        Sliding-window length, samples (0: none).
    fit_window : int
        Samples of the prediction-fit window.
    wait_for_history : bool
        Update a row only once its regressor is complete (as batch ARX).
    trigger : str
        Topic completing a sample ('' : the first input's topic).
    publish_rate : float
        Publications per second of the node's clock, Hz.
    complete_on_next : bool
        Release a completed stamp's sample at the next stamp's first message.
    identify_from : float
        Sample stamp from which samples reach the ARX, s (0: all).
    identify_until : float
        Sample stamp after which samples do not reach the ARX, s (0: no end).
    """

    outputs: tuple[str, ...] = setting(
        (field_channel(0, 'x'),), 'output channels (bag converter syntax)', _channels
    )
    inputs: tuple[str, ...] = setting(
        (_INPUT_UX,), 'input channels (bag converter syntax)', _channels
    )
    na: tuple[int, ...] = setting((2,), 'orders of A: one for all, or ny*ny row by row', _orders)
    nb: tuple[int, ...] = setting(
        (2,), 'numbers of B coefficients: one, or ny*nu row by row', _orders
    )
    nk: tuple[int, ...] = setting((1,), 'input delays, samples: one, or ny*nu row by row', _orders)
    forgetting: float = setting(
        1.0, 'forgetting factor (1: none, as MATLAB recursiveARX)', number(0, above=True, high=1)
    )
    initial_covariance: float = setting(
        1e4, 'P0 = initial_covariance * I (as MATLAB)', number(0, above=True)
    )
    window: int = setting(0, 'sliding window of the estimate, samples (0: none)', integer(0))
    fit_window: int = setting(1000, 'samples of the prediction-fit window', integer(2))
    wait_for_history: bool = setting(
        True, 'update once the regressor is complete (as batch arx); false: zeros before'
    )
    trigger: str = setting('', "topic completing a sample ('': the first input's topic)")
    publish_rate: float = setting(
        10.0, 'model, error, fit and diagnostics per second, Hz', number(0, above=True)
    )
    complete_on_next: bool = setting(
        False,
        "release a stamp's sample at the next stamp's first message, so the header-less "
        'commands in between are its input (stamped trigger; real-time bursts)',
    )
    identify_from: float = setting(
        0.0,
        'sample stamp from which samples are given to the ARX, s (0: all; earlier '
        'samples still set the held values)',
        number(0),
        mutable=True,
    )
    identify_until: float = setting(
        0.0,
        'sample stamp after which samples are not given to the ARX, s (0: no end)',
        number(0),
        mutable=True,
    )

    def __post_init__(self) -> None:
        check_settings(self, IdentificationConfigError)
        if self.identify_until and self.identify_until < self.identify_from:
            raise IdentificationConfigError(
                f'identify_until must be 0 (no end) or >= identify_from {self.identify_from:g}, '
                f'got {self.identify_until:g}'
            )

    @property
    def window_ns(self) -> tuple[int, int | None]:
        """``(identify_from, identify_until)`` in ns of sample stamps (None: no end)."""
        return round(self.identify_from * 1e9), round(self.identify_until * 1e9) or None


@dataclass(frozen=True)
class IdentificationReport:
    """A snapshot to publish.

    Attributes
    ----------
    status : IdentifierStatus
        Samples, coefficients, prediction error, fit, covariance trace, drift.
    layout : CoefficientLayout or None
        The coefficients with their labels (None before the first sample).
    outputs : tuple of str
        Output channel names.
    level : int
        Diagnostic level: 0 OK, 2 ERROR (a non-finite estimate).
    message : str
        Diagnostic message.
    values : dict
        Diagnostic key/values.
    """

    status: IdentifierStatus
    layout: CoefficientLayout | None
    outputs: tuple[str, ...]
    level: int
    message: str
    values: dict[str, object]


def message_type_of(topic: str) -> str:
    """Message type (``pkg/msg/Type``) of a topic of the contract (``docs/topics.md``).

    Parameters
    ----------
    topic : str
        Topic name, with or without the leading ``/``.

    Returns
    -------
    str

    Raises
    ------
    BagError
        If the topic is not in the topic contract.
    """
    relative = topic.lstrip('/')
    if _FIELD_TOPIC.match(relative):
        return FIELD_MESSAGE_TYPE
    for name, kind in MESSAGE_TYPES.items():
        if name.lstrip('/') == relative:
            return kind
    raise BagError(
        f'channel topic {topic!r} is not in the topic contract (docs/topics.md); '
        f'known: {field_topic(0)} .., {", ".join(sorted(MESSAGE_TYPES))}'
    )


def _shaped(name: str, values: tuple[int, ...], rows: int, cols: int) -> object:
    if len(values) == 1:
        return values[0]
    if len(values) != rows * cols:
        raise BagError(
            f'{name} must have 1 or {rows}*{cols} = {rows * cols} values, got {list(values)}'
        )
    return np.array(values, dtype=int).reshape(rows, cols)


def _has_header(msgtype: str) -> bool:
    fields = dict(jazzy_typestore().fielddefs[msgtype][1])
    return 'header' in fields


class OnlineIdentification:
    """Recursive ARX of live messages (see the module docstring).

    Parameters
    ----------
    config : OnlineIdentificationConfig
        Channels, orders, options and window.
    depth : int
        Incomplete stamps kept at most (a read of many samples per topic needs
        at least its length).

    Raises
    ------
    BagError
        A bad channel spec, a topic outside the contract, a trigger no channel
        reads, or orders that do not fit the channels.
    """

    def __init__(self, config: OnlineIdentificationConfig, depth: int = 1024) -> None:
        self.config = config
        ny, nu = len(config.outputs), len(config.inputs)
        outputs, inputs = (
            [resolve_channel(parse_channel(s), message_type_of) for s in specs]
            for specs in (config.outputs, config.inputs)
        )
        #: topic -> message type, every topic the channels read
        self.types = {t: message_type_of(t) for c in outputs + inputs for t in c.topics}
        headers = {t for t, kind in self.types.items() if _has_header(kind)}
        self.stamped = frozenset(headers - COMMAND_TOPICS)  # the topics of a sample
        # commands stamped with their sample, paired by stamp with the samples (if any)
        held_stamped = headers & COMMAND_TOPICS if self.stamped else frozenset()
        trigger = normalize_topic(config.trigger) if config.trigger else None
        first = (inputs or outputs)[0].topics[0]
        if (trigger or first) in held_stamped and self.stamped:
            # a sample is paired with its command by stamp: its own set completes it
            trigger = [t for t in self.types if t in self.stamped][-1]
        self.identifier = ident = ChannelIdentifier(
            outputs,
            inputs,
            _shaped('na', config.na, ny, ny),
            _shaped('nb', config.nb, ny, nu),
            _shaped('nk', config.nk, ny, nu),
            trigger=trigger,
            forgetting=config.forgetting,
            initial_covariance=config.initial_covariance,
            window=config.window or None,
            fit_window=config.fit_window,
            wait_for_history=config.wait_for_history,
        )
        self.aligner = StampAligner(
            ident.topics,
            self.stamped,
            ident.sampler.trigger,
            depth=depth,
            complete_on_next=config.complete_on_next,
            held_stamped=held_stamped,
        )
        self.set_window(*config.window_ns)
        self.rejected = 0  # samples the ARX refused (non-finite values)
        self.outside = 0  # samples outside the window
        self.last_error: np.ndarray | None = None
        self._stamp: int | None = None  # stamp of the newest sample-topic message released

    @property
    def samples(self) -> int:
        """Samples given to the ARX since the start or the last reset."""
        return self.identifier.arx.samples

    def set_window(self, first_ns: int, last_ns: int | None) -> None:
        """Identify the samples stamped in ``[first_ns, last_ns]`` only (None: no end).

        Parameters
        ----------
        first_ns : int
            First sample stamp identified, ns.
        last_ns : int or None
            Last sample stamp identified, ns.
        """
        self._window = (int(first_ns), None if last_ns is None else int(last_ns))

    def add(self, topic: str, message: object) -> int:
        """Take one message; identify the samples it completes.

        Parameters
        ----------
        topic : str
            Its topic (absolute, one of :attr:`types`).
        message : object
            The message (rclpy or rosbags; a sample topic's has a header).

        Returns
        -------
        int
            Samples given to the ARX.
        """
        stamp = None
        if topic in self.stamped or topic in self.aligner.held_stamped:
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
        samples = []
        for name, (released_stamp, item) in self.aligner.add(topic, stamp, (stamp, message)):
            if name in self.aligner.stamped:
                self._stamp = released_stamp
            sample = self.identifier.sampler.add(name, item)
            if sample is None:
                continue
            first, last = self._window
            if self._stamp is not None and (
                self._stamp < first or (last is not None and self._stamp > last)
            ):
                self.outside += 1  # its values stay held: the next sample's regressor
                continue
            samples.append(sample)
        self._identify(samples)
        return len(samples)

    def _identify(self, samples: list) -> None:
        """Give the ARX the samples in one compiled call; one at a time if one is refused."""
        if not samples:
            return
        arx = self.identifier.arx
        try:
            errors = arx.update_many(
                np.array([y for y, _ in samples]), np.array([u for _, u in samples])
            )
        except ValueError:
            for y, u in samples:
                try:
                    self.last_error = arx.update(y, u)
                except ValueError:
                    self.rejected += 1
            return
        self.last_error = errors[-1]

    def reset(self) -> int:
        """Return the estimate to ``theta = 0``, ``P = p0 I``; forget held and pending messages.

        Returns
        -------
        int
            Samples discarded.
        """
        discarded = self.samples
        self.identifier.reset()
        self.aligner.reset()
        self.last_error = None
        self._stamp = None
        return discarded

    def report(self) -> IdentificationReport:
        """Return what to publish now (see :class:`IdentificationReport`)."""
        status = self.identifier.status()
        counts = self.identifier.sampler.counts
        if status.samples == 0:
            level, message = OK, 'waiting for complete samples'
        elif not np.all(np.isfinite(status.theta)):
            level, message = ERROR, 'estimate not finite: reset it'
        else:
            level, message = OK, 'estimating'
        values = {
            'samples': status.samples,
            'covariance trace': f'{status.covariance_trace:.9g}',
            'parameter drift': f'{status.drift:.9g}',
            'relative parameter drift': f'{status.relative_drift:.9g}',
            'fit (%)': ' '.join(f'{f:.3f}' for f in status.fit),
            'incomplete stamps dropped': self.aligner.dropped,
            'samples with held values': counts.held,
            'messages without the field': counts.bad,
            'samples rejected': self.rejected,
            'samples outside the window': self.outside,
        }
        layout = self.identifier.layout() if status.samples else None
        outputs = self.identifier.sampler.names[0]
        return IdentificationReport(status, layout, outputs, level, message, values)

    def describe(self) -> str:
        """Return one line: the model, its orders, the trigger and the sample topics."""
        cfg, (outs, ins) = self.config, self.identifier.sampler.names
        stamped = ', '.join(sorted(self.stamped)) or 'none'
        return (
            f'recursive ARX {" ".join(outs)} <- {" ".join(ins)}, na {list(cfg.na)} nb '
            f'{list(cfg.nb)} nk {list(cfg.nk)}, forgetting {cfg.forgetting:g}, sample on '
            f'{self.identifier.sampler.trigger} (stamped: {stamped})'
        )
