"""Plain readings the collector takes (ROS graph, node → pid, processes, topics), before the model.

They cross from the side-effecting readers (rclpy, psutil) to the pure `build_model`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Endpoint:
    """One publisher or subscription of a topic, as the DDS graph reports it."""

    node: str  # fully qualified node name
    topic: str
    type: str
    gid: bytes
    # reliability, durability, history, liveliness (str); depth, deadline_ns, liveliness_lease_ns (int)
    qos: dict[str, Any]


@dataclass
class NodeReading:
    """One ROS node and its per-node graph lists (names → types)."""

    fqn: str
    name: str
    namespace: str
    instances: int = 1  # how many nodes DDS lists under this name (two launches of one node)
    services: dict[str, list[str]] = field(default_factory=dict)
    clients: dict[str, list[str]] = field(default_factory=dict)
    action_servers: dict[str, list[str]] = field(default_factory=dict)
    action_clients: dict[str, list[str]] = field(default_factory=dict)


@dataclass
class GraphReading:
    """The ROS graph at one moment (internal names already filtered out unless asked for)."""

    nodes: dict[str, NodeReading] = field(default_factory=dict)
    topics: dict[str, list[str]] = field(default_factory=dict)  # topic -> types
    publishers: dict[str, list[Endpoint]] = field(default_factory=dict)  # topic -> endpoints
    subscribers: dict[str, list[Endpoint]] = field(default_factory=dict)
    rosout_gids: dict[str, bytes] = field(default_factory=dict)  # node fqn -> gid of its /rosout pub
    participants: dict[str, int] = field(default_factory=dict)  # node fqn -> participants with its /rosout
    publisher_gids: dict[str, dict[bytes, str]] = field(default_factory=dict)  # topic -> gid -> node
    service_events: dict[str, str] = field(default_factory=dict)  # service -> its event topic's type
    goal_status: dict[str, list[str]] = field(default_factory=dict)  # action status topic -> servers
    goal_feedback: dict[str, str] = field(default_factory=dict)  # action feedback topic -> its type
    skipped: dict[str, str] = field(default_factory=dict)  # node fqn -> why it was skipped
    qos_version: int = 0  # `QosCache.version`: changes when an endpoint's QoS changed in place


@dataclass(frozen=True)
class PidInfo:
    """Which process a node lives in: ``status`` confirmed | unverified | ambiguous | unknown | remote."""

    pid: int | None
    status: str
    candidates: tuple[int, ...] = ()
    prefix: str = ""


@dataclass
class ProcessReading:
    """One OS process: identity, its parent and metrics (SCHEMAS["process"] names; missing = unknown)."""

    pid: int
    ppid: int | None
    name: str = ""
    cmdline: str = ""
    create_time: float | None = None
    username: str | None = None
    metrics: dict[str, float] = field(default_factory=dict)
    alive: bool = True
    unreadable: list[str] = field(default_factory=list)  # fields we were denied


@dataclass
class TopicStats:
    """Metrics of one topic over the sliding window; ``measured`` False says why not in ``reason``."""

    measured: bool
    reason: str = ""
    metrics: dict[str, float] = field(default_factory=dict)
    by_publisher: dict[bytes, float] = field(default_factory=dict)  # publisher gid -> messages/s
    age_by_publisher: dict[bytes, float] = field(default_factory=dict)  # publisher gid -> mean age ms
    stamp_resets: list[tuple[int, int]] = field(default_factory=list)  # (received ns, back ns)
    stamp_partners: dict[str, float] = field(default_factory=dict)  # topic -> share of stamps it also has
