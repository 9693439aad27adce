"""The demo robot (and generated systems) described as plain data: groups → nodes → endpoints.

A :class:`Topology` is the ground truth the tests and the evaluation compare against: which
processes (groups) exist, which nodes each hosts, and which topics, services and edges they have.
The same data drives the process entry (``Topology.entry``: :mod:`stream_viz.demo.robot_process` for
the demo robot and generated systems), so what runs is what is described.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

from stream_viz.demo.faults import BASIC_FAULTS, FaultSpec
from stream_viz.errors import DemoError
from stream_viz.model.ids import make_id

ENTRY = "stream_viz.demo.robot_process"


@dataclass(frozen=True)
class PubSpec:
    """One publisher of a node.

    ``rate`` (Hz) drives a timer when ``trigger`` is empty; otherwise the node publishes once per
    message received on the topic ``trigger`` and ``rate`` is the expected rate. ``requires`` names
    inputs (topics or services) that must have delivered within ``max_age`` seconds, else the
    publish is skipped (that is how a fault upstream propagates downstream).
    """

    topic: str
    type: str
    rate: float
    trigger: str = ""
    requires: tuple[str, ...] = ()
    max_age: float = 1.0


@dataclass(frozen=True)
class SubSpec:
    """One subscription of a node."""

    topic: str
    type: str


@dataclass(frozen=True)
class ServiceSpec:
    """A service server of a node."""

    name: str
    type: str


@dataclass(frozen=True)
class ClientSpec:
    """A service client calling ``name`` every ``period`` s; a call older than ``timeout`` s is dropped."""

    name: str
    type: str
    period: float
    timeout: float = 3.0


@dataclass(frozen=True)
class NodeSpec:
    """A ROS node: fully qualified ``name`` and its endpoints."""

    name: str
    pubs: tuple[PubSpec, ...] = ()
    subs: tuple[SubSpec, ...] = ()
    services: tuple[ServiceSpec, ...] = ()
    clients: tuple[ClientSpec, ...] = ()
    diag_monitor: bool = False  # publishes per-node statuses on /diagnostics (the "diag" fault)


@dataclass(frozen=True)
class GroupSpec:
    """One OS process hosting ``nodes``; ``respawn``: restart it whenever it exits (launch's respawn)."""

    name: str
    nodes: tuple[NodeSpec, ...]
    respawn: bool = False


@dataclass(frozen=True)
class Topology:
    """A whole system: named groups (processes) of nodes.

    ``entry`` is the module run once per group (``python -m ENTRY --group NAME ...``); ``faults`` the
    fault kinds that entry can inject, each with the nodes it applies to (empty: every node).
    """

    name: str
    groups: tuple[GroupSpec, ...] = field(default_factory=tuple)
    entry: str = ENTRY
    faults: tuple[tuple[str, tuple[str, ...]], ...] = tuple((k, ()) for k in BASIC_FAULTS)

    # -- lookups ---------------------------------------------------------------------------
    def nodes(self) -> list[NodeSpec]:
        """All nodes, in group order."""
        return [n for g in self.groups for n in g.nodes]

    def node_names(self) -> list[str]:
        """Fully qualified names of all nodes."""
        return [n.name for n in self.nodes()]

    def group(self, name: str) -> GroupSpec:
        """The group called ``name`` (DemoError naming the groups otherwise)."""
        for g in self.groups:
            if g.name == name:
                return g
        raise DemoError(f"unknown group {name!r} in topology {self.name!r}; "
                        f"groups: {', '.join(g.name for g in self.groups)}")

    def group_of(self, node: str) -> str:
        """Name of the group (process) hosting ``node`` (fqn)."""
        for g in self.groups:
            if any(n.name == node for n in g.nodes):
                return g.name
        raise DemoError(f"unknown node {node!r} in topology {self.name!r}; "
                        f"nodes: {', '.join(self.node_names())}")

    def check_fault(self, fault: FaultSpec) -> None:
        """Raise DemoError unless this system can inject ``fault`` (its kind, into its target)."""
        kinds = dict(self.faults)
        if fault.fault not in kinds:
            raise DemoError(f"{self.name} cannot inject {fault.fault!r}; its faults: {', '.join(kinds)}")
        fault.check(list(kinds[fault.fault]) or self.node_names())

    def diag_monitor(self) -> str | None:
        """Fqn of the node publishing per-node diagnostics, if any."""
        return next((n.name for n in self.nodes() if n.diag_monitor), None)

    def topics(self) -> dict[str, str]:
        """Topic name → message type for every topic published or subscribed (no /rosout)."""
        out: dict[str, str] = {}
        for n in self.nodes():
            for e in (*n.pubs, *n.subs):
                out[e.topic] = e.type
            if n.diag_monitor:
                out["/diagnostics"] = "diagnostic_msgs/msg/DiagnosticArray"
        return out

    def services(self) -> dict[str, str]:
        """Service name → type for every service served."""
        return {s.name: s.type for n in self.nodes() for s in n.services}

    def edges(self) -> set[tuple[str, str, str]]:
        """Layer-0 edges as member ids: ``(node, topic, "pub")``, ``(topic, node, "sub")``,
        ``(client node, server node, "send")`` — the model's data-flow direction."""
        out: set[tuple[str, str, str]] = set()
        servers = {s.name: n.name for n in self.nodes() for s in n.services}
        for n in self.nodes():
            nid = make_id("node", n.name)
            for p in n.pubs:
                out.add((nid, make_id("topic", p.topic), "pub"))
            if n.diag_monitor:
                out.add((nid, make_id("topic", "/diagnostics"), "pub"))
            for s in n.subs:
                out.add((make_id("topic", s.topic), nid, "sub"))
            for c in n.clients:
                if c.name in servers:
                    out.add((nid, make_id("node", servers[c.name]), "send"))
        return out

    # -- serialisation ---------------------------------------------------------------------
    def to_data(self) -> dict:
        """Plain JSON-able data."""
        return asdict(self)

    @staticmethod
    def from_data(data: dict) -> Topology:
        """Inverse of :meth:`to_data`."""
        try:
            groups = tuple(
                GroupSpec(g["name"], tuple(
                    NodeSpec(
                        name=n["name"],
                        pubs=tuple(PubSpec(**{**p, "requires": tuple(p.get("requires", ()))})
                                   for p in n.get("pubs", ())),
                        subs=tuple(SubSpec(**s) for s in n.get("subs", ())),
                        services=tuple(ServiceSpec(**s) for s in n.get("services", ())),
                        clients=tuple(ClientSpec(**c) for c in n.get("clients", ())),
                        diag_monitor=bool(n.get("diag_monitor", False)),
                    ) for n in g["nodes"]), bool(g.get("respawn", False)))
                for g in data["groups"])
            faults = tuple((k, tuple(ts)) for k, ts in data.get("faults", Topology.faults))
        except (KeyError, TypeError, ValueError) as exc:
            raise DemoError(f"malformed topology data: {exc}") from exc
        return Topology(data.get("name", "topology"), groups, data.get("entry", ENTRY), faults)

    def save(self, path: str | Path) -> Path:
        """Write the topology as JSON to ``path``."""
        path = Path(path)
        path.write_text(json.dumps(self.to_data()))
        return path

    @staticmethod
    def load(path: str | Path) -> Topology:
        """Read a topology written by :meth:`save`."""
        try:
            return Topology.from_data(json.loads(Path(path).read_text()))
        except (OSError, ValueError) as exc:
            raise DemoError(f"cannot read topology {path}: {exc}") from exc


# -- the demo robot ------------------------------------------------------------------------
_T = {
    "scan": "sensor_msgs/msg/LaserScan",
    "image": "sensor_msgs/msg/Image",
    "imu": "sensor_msgs/msg/Imu",
    "odom": "nav_msgs/msg/Odometry",
    "obstacles": "geometry_msgs/msg/PoseArray",
    "pose": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "plan": "nav_msgs/msg/Path",
    "twist": "geometry_msgs/msg/Twist",
    "wheel": "std_msgs/msg/Float64MultiArray",
    "battery": "sensor_msgs/msg/BatteryState",
    "getmap": "nav_msgs/srv/GetMap",
}

DEMO = Topology("demo_robot", (
    GroupSpec("lidar", (
        NodeSpec("/lidar_driver", pubs=(PubSpec("/scan", _T["scan"], 10.0),)),
    )),
    GroupSpec("camera", (
        NodeSpec("/camera_driver", pubs=(PubSpec("/camera/image_raw", _T["image"], 15.0),)),
    )),
    GroupSpec("base", (
        NodeSpec("/imu_driver", pubs=(PubSpec("/imu", _T["imu"], 50.0),)),
        NodeSpec("/wheel_odometry", pubs=(PubSpec("/odom", _T["odom"], 20.0),)),
        NodeSpec("/controller", subs=(SubSpec("/cmd_vel", _T["twist"]),),
                 pubs=(PubSpec("/wheel_cmd", _T["wheel"], 10.0, trigger="/cmd_vel"),)),
    )),
    GroupSpec("navigation", (
        NodeSpec("/obstacle_detector",
                 subs=(SubSpec("/scan", _T["scan"]), SubSpec("/camera/image_raw", _T["image"])),
                 pubs=(PubSpec("/obstacles", _T["obstacles"], 10.0, trigger="/scan"),)),
        NodeSpec("/localization",
                 subs=(SubSpec("/imu", _T["imu"]), SubSpec("/odom", _T["odom"])),
                 pubs=(PubSpec("/pose", _T["pose"], 20.0, trigger="/odom",
                               requires=("/imu",), max_age=0.5),)),
    )),
    GroupSpec("planning", (
        NodeSpec("/global_planner",
                 clients=(ClientSpec("/map_server/get_map", _T["getmap"], period=2.0, timeout=3.0),),
                 subs=(SubSpec("/pose", _T["pose"]),),
                 pubs=(PubSpec("/plan", _T["plan"], 1.0, requires=("/map_server/get_map", "/pose"),
                               max_age=5.0),)),
        NodeSpec("/local_planner",
                 subs=(SubSpec("/pose", _T["pose"]), SubSpec("/obstacles", _T["obstacles"]),
                       SubSpec("/plan", _T["plan"])),
                 pubs=(PubSpec("/cmd_vel", _T["twist"], 10.0, trigger="/obstacles",
                               requires=("/pose", "/plan"), max_age=3.0),)),
    )),
    GroupSpec("map", (
        NodeSpec("/map_server", services=(ServiceSpec("/map_server/get_map", _T["getmap"]),)),
    )),
    GroupSpec("monitor", (
        NodeSpec("/system_monitor", diag_monitor=True),
        NodeSpec("/battery_monitor", subs=(SubSpec("/wheel_cmd", _T["wheel"]),),
                 pubs=(PubSpec("/battery_state", _T["battery"], 1.0),)),
    )),
))
