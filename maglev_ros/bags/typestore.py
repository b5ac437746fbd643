"""Message definitions for reading and writing bags: ROS 2 Jazzy's plus the bag's own.

Deserialisation uses the type store's generated little/big-endian CDR readers
directly (:func:`cdr_deserializer`).  Unlike ``Typestore.deserialize_cdr`` they
accept trailing padding after the message: Fast DDS (and so ``rclpy``'s
``serialize_message`` and ``ros2 bag record``) can hand out buffers a few bytes
longer than the message, which the strict size check rejects.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable

from rosbags.interfaces import Connection, MessageDefinitionFormat
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from maglev_ros.cdr.typestore import jazzy_typestore

from .errors import BagError

__all__ = ['bag_typestore', 'cdr_deserializer', 'jazzy_typestore']


def bag_typestore(connections: Iterable[Connection]) -> Typestore:
    """Return a type store that knows every message type of a bag.

    Standard types come from ROS 2 Jazzy; other types are registered from the
    definitions the bag embeds (MCAP schemas, sqlite3 ``message_definitions``).

    Parameters
    ----------
    connections : iterable of rosbags Connection
        The bag's connections.

    Returns
    -------
    rosbags Typestore
        Jazzy's store, or a copy extended with the bag's own types.
    """
    base = jazzy_typestore()
    extra: dict = {}
    for conn in connections:
        if conn.msgtype in base.fielddefs or conn.msgtype in extra:
            continue
        text = conn.msgdef.data
        try:
            if conn.msgdef.format == MessageDefinitionFormat.MSG:
                extra.update(get_types_from_msg(text, conn.msgtype))
            elif conn.msgdef.format == MessageDefinitionFormat.IDL:
                sep = '=' * 80 + '\n'
                chunks = text.split(sep)[1:] if text.startswith(sep + 'IDL: ') else [text]
                for chunk in chunks:
                    extra.update(
                        get_types_from_idl(
                            chunk.split('\n', 1)[-1] if chunk.startswith('IDL: ') else chunk
                        )
                    )
        except Exception as exc:  # any parser failure
            raise BagError(
                f'cannot parse the definition of {conn.msgtype!r} stored in the '
                f'bag for topic {conn.topic!r}: {exc}'
            ) from None
    if not extra:
        return base
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register({k: v for k, v in extra.items() if k not in store.fielddefs})
    return store


def cdr_deserializer(typestore: Typestore, msgtype: str) -> Callable[[bytes], object]:
    """Return a fast CDR deserialiser for one message type.

    Parameters
    ----------
    typestore : rosbags Typestore
        Store that knows ``msgtype``.
    msgtype : str
        Message type ``pkg/msg/Type``.

    Returns
    -------
    callable
        ``f(raw) -> message`` for CDR bytes with their 4-byte encapsulation header;
        raises :class:`BagError` on bytes that are not a ``msgtype`` message.
    """
    if msgtype not in typestore.fielddefs:
        raise BagError(
            f'message type {msgtype!r} is neither a ROS 2 Jazzy standard type '
            f'nor defined in the bag'
        )
    msgdef = typestore.get_msgdef(msgtype)
    little, big, cls = msgdef.deserialize_cdr_le, msgdef.deserialize_cdr_be, msgdef.cls

    def deserialize(raw: bytes) -> object:
        try:
            if len(raw) >= 4 and raw[0] == 0:
                if raw[1] == 1:
                    return little(raw[4:], 0, cls, typestore)[0]
                if raw[1] == 0:
                    return big(raw[4:], 0, cls, typestore)[0]
        except Exception as exc:  # struct/decode errors: corrupt data
            raise BagError(
                f'cannot deserialise a {msgtype} message ({len(raw)} bytes): {exc}'
            ) from None
        raise BagError(f'a {msgtype} message ({len(raw)} bytes) has no CDR encapsulation header')

    return deserialize
