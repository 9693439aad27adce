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


def diagnostic_array(stamp_ns: int, rows: Iterable[tuple[int, str, str, str, list[tuple[str, str]]]],
                     frame_id: str = "") -> bytes:
    """Return the serialized DiagnosticArray of ``rows`` (level, name, message, hardware id,
    key-values) stamped ``stamp_ns``."""
    rows = list(rows)
    out = [ENCAPSULATION, struct.pack("<iI", stamp_ns // 1_000_000_000, stamp_ns % 1_000_000_000)]
    put, u32, pads = out.append, _U32.pack, _PADS
    at = 8  # payload offset: alignment counts from the payload's start

    def string(s: str) -> None:
        nonlocal at
        b = s.encode()
        pad = -at % 4
        put(pads[pad] + u32(len(b) + 1) + b + b"\x00")
        at += pad + 5 + len(b)

    def count(n: int) -> None:
        nonlocal at
        pad = -at % 4
        put(pads[pad] + u32(n))
        at += pad + 4

    string(frame_id)
    count(len(rows))
    for level, name, message, hardware_id, values in rows:
        put(bytes((level & 0xFF,)))
        at += 1
        string(name)
        string(message)
        string(hardware_id)
        count(len(values))
        for k, v in values:
            string(k)
            string(v)
    return b"".join(out)
