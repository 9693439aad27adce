"""Fixed fields read straight from serialized (CDR) messages, without deserialising them.

A serialized ROS 2 message starts with a 4-byte encapsulation header (``00 01 00 00``: CDR, little
endian); the payload follows, aligned from its own start. Two layouts are read here:

* a message type whose first field is ``header: std_msgs/Header``: ``stamp.sec`` (int32) and
  ``stamp.nanosec`` (uint32) are payload bytes 0–7;
* a service event (``<service>/_service_event``, first field ``info: service_msgs/ServiceEventInfo``):
  ``event_type`` (uint8) at 0, ``stamp`` at 4, ``client_gid`` (uint8[16]) at 12, then
  ``sequence_number`` (int64), at 32 in XCDR1 (8-byte alignment) and at 28 in XCDR2 (4-byte).

Pure functions over ``bytes``.
"""

from __future__ import annotations

import struct
from typing import Any

# Encapsulation kind (second byte) → (byte order, alignment of 8-byte values): CDR BE/LE (XCDR1),
# PLAIN_CDR2 BE/LE (XCDR2). Other kinds (parameter lists, delimited) are not read.
ENCAPSULATIONS = {0x00: (">", 8), 0x01: ("<", 8), 0x06: (">", 4), 0x07: ("<", 4)}
_STAMP = {k: struct.Struct(order + "iI").unpack_from for k, (order, _) in ENCAPSULATIONS.items()}
_SEQ = {k: struct.Struct(order + "q").unpack_from for k, (order, _) in ENCAPSULATIONS.items()}
HEADER_FIELD = ("header", "std_msgs/Header")
EVENT_INFO_FIELD = ("info", "service_msgs/ServiceEventInfo")
# service_msgs/ServiceEventInfo event types
REQUEST_SENT, REQUEST_RECEIVED, RESPONSE_SENT, RESPONSE_RECEIVED = 0, 1, 2, 3


def first_field(msg_type: Any) -> tuple[str, str] | None:
    """Return ``(name, type)`` of the first field of a message class, or None (no fields)."""
    fields = msg_type.get_fields_and_field_types()  # ordered as declared
    return next(iter(fields.items()), None)


def has_header(msg_type: Any) -> bool:
    """Return True if the message class begins with ``header: std_msgs/Header``."""
    return first_field(msg_type) == HEADER_FIELD


def is_service_event(msg_type: Any) -> bool:
    """Return True if the message class is a service event (begins with ``ServiceEventInfo``)."""
    return first_field(msg_type) == EVENT_INFO_FIELD


def header_stamp_ns(raw: bytes) -> int | None:
    """Return ``header.stamp`` in ns of a serialized message that begins with a Header.

    None when the bytes are too short, the encapsulation is not one of `ENCAPSULATIONS`, or the
    stamp is zero (a publisher that never set it: no time to compare with).
    """
    if len(raw) < 12 or raw[0] != 0 or raw[1] not in _STAMP:
        return None
    sec, nanosec = _STAMP[raw[1]](raw, 4)
    if sec == 0 and nanosec == 0:
        return None
    return sec * 1_000_000_000 + nanosec


def service_event_info(raw: bytes) -> tuple[int, int, bytes, int] | None:
    """Return ``(event_type, stamp ns, client_gid, sequence_number)`` of a serialized service event.

    None when the bytes are too short or the encapsulation is not one of `ENCAPSULATIONS`.
    """
    if len(raw) < 12 or raw[0] != 0 or raw[1] not in ENCAPSULATIONS:
        return None
    kind = raw[1]
    seq_at = 4 + (32 if ENCAPSULATIONS[kind][1] == 8 else 28)
    if len(raw) < seq_at + 8:
        return None
    sec, nanosec = _STAMP[kind](raw, 8)
    return raw[4], sec * 1_000_000_000 + nanosec, bytes(raw[16:32]), _SEQ[kind](raw, seq_at)[0]
