"""maglev_ros.hardware: the Maggy board protocols and a virtual board (ROS-free).

Re-exports only; see the modules: ``packet`` (V2x command packets),
``v2x_stream`` (V2x record decoder), ``v4x_telemetry`` (V4x text telemetry),
``scaling`` (current <-> PWM), ``board_clock`` (board time to host time),
``command_guard`` (which commands reach the coils, as PWM counts),
``board_stream`` (the board's bytes to stamped samples in SI units),
``board_session`` (the driver's board: link thread, samples to publish, guarded
commands, timeout, zero on close),
``serial_link`` (the port handle), ``firmware`` (board emulators),
``physics_plant`` (the physics simulator as an emulator plant),
``virtual_board`` (an emulator on a pty), and for the V4x PC-control firmware
``cobs_frame`` (COBS frames), ``v4x_pc_protocol`` (its messages),
``v4x_pc_link`` (the request/response link), ``v4x_pc_poller`` (the driver's loop on
it) and ``v4x_pc_firmware`` (its emulator).
"""

from .board_clock import BoardClock
from .board_stream import BoardStream, StreamOutput
from .cobs_frame import FrameError, FrameSplitter, decode_frame, encode_frame
from .command_guard import CommandGuard, GuardDecision, pair_differences
from .firmware import LinearPlant, Plant, V2xFirmware, V4xFirmware
from .packet import (
    CommandParser,
    PacketError,
    decode_command,
    encode_command,
    is_sendable,
    sendable_pwm,
)
from .physics_plant import MAGNET_MODES, SimulatorPlant, make_simulator_plant
from .scaling import CurrentScaling, ScalingError
from .serial_link import Backoff, LinkError, SerialLink
from .v2x_stream import (
    DecoderStats,
    PlausibilityBounds,
    RecordBatch,
    RecordDecoder,
    pack_records,
    record_dtype,
    record_size,
)
from .v4x_pc_firmware import V4xPcFirmware
from .v4x_pc_link import BoardReplyError, ReplyTimeoutError, V4xPcLink
from .v4x_pc_poller import V4xPcPoller
from .v4x_telemetry import (
    InfoMessage,
    Severity,
    TelemetryError,
    TelemetrySample,
    TelemetryStats,
    TelemetryStream,
    format_telemetry_line,
    parse_telemetry_line,
)
from .virtual_board import BoardStatus, VirtualBoard, VirtualBoardError

__all__ = [
    'MAGNET_MODES',
    'Backoff',
    'BoardReplyError',
    'FrameError',
    'FrameSplitter',
    'ReplyTimeoutError',
    'V4xPcFirmware',
    'V4xPcLink',
    'V4xPcPoller',
    'decode_frame',
    'encode_frame',
    'pair_differences',
    'BoardClock',
    'BoardStatus',
    'BoardStream',
    'CommandGuard',
    'GuardDecision',
    'CommandParser',
    'CurrentScaling',
    'DecoderStats',
    'InfoMessage',
    'LinearPlant',
    'LinkError',
    'PacketError',
    'Plant',
    'PlausibilityBounds',
    'RecordBatch',
    'RecordDecoder',
    'ScalingError',
    'SerialLink',
    'Severity',
    'SimulatorPlant',
    'StreamOutput',
    'TelemetryError',
    'TelemetrySample',
    'TelemetryStats',
    'TelemetryStream',
    'V2xFirmware',
    'V4xFirmware',
    'VirtualBoard',
    'VirtualBoardError',
    'decode_command',
    'encode_command',
    'format_telemetry_line',
    'is_sendable',
    'make_simulator_plant',
    'pack_records',
    'parse_telemetry_line',
    'record_dtype',
    'record_size',
    'sendable_pwm',
]
