"""A ``diagnostic_msgs/DiagnosticArray`` written straight as CDR (what rclpy would serialize). Pure.

The agent publishes one per sample; building hundreds of rclpy ``KeyValue`` objects and
serializing them cost it more than its reading of ``/proc`` (bench/bench_agent.py, docs/hosts.md).
Layout (XCDR1, little endian, alignment from the payload's start): ``header`` (``stamp.sec``
int32, ``stamp.nanosec`` uint32, ``frame_id`` string), then ``status``, a sequence (uint32
count) of ``level`` (byte), ``name``, ``message``, ``hardware_id`` (strings) and ``values``, a
sequence of ``key``, ``value`` strings. A string is a uint32 length (with its NUL), the UTF-8
bytes, a NUL.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable

ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR, little endian
_U32 = struct.Struct("<I")
_PADS = (b"", b"\x00", b"\x00\x00", b"\x00\x00\x00")


def _string(out: list[bytes], at: int, s: str) -> int:
    """Append string ``s`` at payload offset ``at`` (padded to 4 first); return the offset after it."""
    b = s.encode()
    pad = -at % 4
    out.append(_PADS[pad] + _U32.pack(len(b) + 1) + b + b"\x00")
    return at + pad + 5 + len(b)


def _u32(out: list[bytes], at: int, n: int) -> int:
    pad = -at % 4
    out.append(_PADS[pad] + _U32.pack(n))
    return at + pad + 4


def diagnostic_array(stamp_ns: int, rows: Iterable[tuple[int, str, str, str, list[tuple[str, str]]]],
                     frame_id: str = "") -> bytes:
    """Return the serialized DiagnosticArray of ``rows`` (level, name, message, hardware id,
    key-values) stamped ``stamp_ns``."""
    rows = list(rows)
    out = [ENCAPSULATION, struct.pack("<iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)]
    at = _string(out, 8, frame_id)
    at = _u32(out, at, len(rows))
    for level, name, message, hardware_id, values in rows:
        out.append(bytes((level & 0xFF,)))
        at = _string(out, at + 1, name)
        at = _string(out, at, message)
        at = _string(out, at, hardware_id)
        at = _u32(out, at, len(values))
        for k, v in values:
            at = _string(out, at, k)
            at = _string(out, at, v)
    return b"".join(out)
