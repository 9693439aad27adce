"""Fast DDS GUIDs: the only RMW-specific code of the collector.

A Fast DDS ``endpoint_gid`` (16 bytes, as rmw_fastrtps reports it) starts with the GUID prefix of
the participant: bytes 0–1 the vendor id ``01 0f`` (eProsima), 2–3 a host id, 4–5 the low 16 bits
of the creating process's PID (little-endian), 6–7 random, 8–11 the participant index; 12–15 are
the entity id. All nodes of one process share one participant, hence one prefix.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

FASTDDS_VENDOR = b"\x01\x0f"


@dataclass(frozen=True)
class GidInfo:
    """What a Fast DDS endpoint gid says about where the endpoint lives."""

    prefix: str  # hex of bytes 0–11: the participant's GUID prefix (cache key)
    host_id: int  # bytes 2–3, big-endian as read
    pid_low16: int  # PID & 0xFFFF of the process that created the participant
    participant: int  # bytes 8–11, little-endian


def decode_gid(gid: bytes | Sequence[int]) -> GidInfo | None:
    """Decode a Fast DDS endpoint gid; None when it is not a Fast DDS gid (other vendor, too short).

    Parameters
    ----------
    gid : bytes or sequence of int
        The ``endpoint_gid`` of a ``TopicEndpointInfo`` (rclpy gives a list of ints).
    """
    b = bytes(gid)
    if len(b) < 12 or b[:2] != FASTDDS_VENDOR:
        return None
    return GidInfo(
        prefix=b[:12].hex(),
        host_id=int.from_bytes(b[2:4], "big"),
        pid_low16=int.from_bytes(b[4:6], "little"),
        participant=int.from_bytes(b[8:12], "little"),
    )
