"""Read the ROS 2 graph through an rclpy node with graph API calls only (no spinning, no calls).

Hidden names (a token starting with ``_``, e.g. ``/fib/_action/feedback``) and the per-node
infrastructure (parameter services, ``get_type_description``, ``/rosout``, ``/parameter_events``)
are left out by default: they would swamp the model and tie every node to every other.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

from rclpy.node import Node, NodeNameNonExistentError

from stream_viz.collect.goals import FEEDBACK_SUFFIX, GOAL_STATUS_TYPE, STATUS_SUFFIX
from stream_viz.collect.graphsignal import GraphSignal
from stream_viz.collect.readings import Endpoint, GraphReading, NodeReading
from stream_viz.collect.services import EVENT_SUFFIX
from stream_viz.model.ids import node_fqn

UNKNOWN_NODE = "_NODE_NAME_UNKNOWN_"
PARAM_SERVICES = frozenset({
    "describe_parameters", "get_parameters", "get_parameter_types", "list_parameters",
    "set_parameters", "set_parameters_atomically", "get_type_description",
})
INFRA_TOPICS = frozenset({"/rosout", "/parameter_events"})
ACTION_GOAL_SUFFIX = "/_action/send_goal"


def is_hidden(name: str) -> bool:
    """Return True for a hidden ROS name (any token starts with ``_``)."""
    return name.startswith("_") or "/_" in name


def is_param_service(name: str, node_fqn_: str) -> bool:
    """Return True for one of the standard per-node parameter / type-description services."""
    base, _, last = name.rpartition("/")
    return base == node_fqn_ and last in PARAM_SERVICES


def qos_dict(qos: Any) -> dict[str, Any]:
    """Return a QoS profile as plain data: policy names lower-case, depth as int, durations in ns.

    ``deadline_ns`` and ``liveliness_lease_ns`` are rmw's: 0 is "unspecified" (the default) and
    `INFINITE_NS` infinite (what discovery reports for an endpoint that set none).
    """
    def pol(p: Any) -> str:
        return getattr(p, "name", str(p)).lower()
    history = pol(qos.history)
    # DDS discovery does not carry history/depth: rmw reports "unknown" and 0, kept as unknown.
    depth = int(qos.depth) if history != "unknown" else None
    return {"reliability": pol(qos.reliability), "durability": pol(qos.durability),
            "history": history, "depth": depth, "deadline_ns": _ns(qos.deadline),
            "liveliness": pol(qos.liveliness), "liveliness_lease_ns": _ns(qos.liveliness_lease_duration)}


INFINITE_NS = 2**63 - 1  # RMW_DURATION_INFINITE in ns


def _ns(duration: Any) -> int:
    return min(int(getattr(duration, "nanoseconds", 0)), INFINITE_NS)


def _actions(services: list[tuple[str, list[str]]]) -> dict[str, list[str]]:
    # rcl_action finds actions exactly so: the ``<action>/_action/send_goal`` service of a node.
    out = {}
    for name, types in services:
        if name.endswith(ACTION_GOAL_SUFFIX):
            out[name[: -len(ACTION_GOAL_SUFFIX)]] = [t.removesuffix("_SendGoal") for t in types]
    return out


def _keep(name: str, include_hidden: bool) -> bool:
    return include_hidden or not is_hidden(name)


class QosCache:
    """QoS per (topic, node, role), refreshed for topics whose endpoint set changed and, a few
    per sample, for those read longest ago.

    ``get_*_info_by_topic`` scans every endpoint of the graph (one call costs O(endpoints)), so
    calling it for every topic every sample is quadratic; per-node queries are cheap. Topics whose
    endpoint set changed are refreshed within ``budget_s`` per sample, the rest on the next
    samples. A node that re-creates an endpoint with another QoS (a lifecycle node configured
    again, a QoS parameter applied) keeps the endpoint set: each topic is also read again once
    its QoS is older than ``every_s``, oldest first, within ``stale_budget_s`` a sample.
    """

    def __init__(self, budget_s: float = 0.03, every_s: float = 5.0, stale_budget_s: float = 0.005) -> None:
        self.budget_s, self.every_s, self.stale_budget_s = budget_s, every_s, stale_budget_s
        self.version = 0  # counts reads that found an endpoint's QoS changed (its set the same)
        self._known: dict[str, frozenset[tuple[str, str]]] = {}
        self._read_at: dict[str, float] = {}  # topic -> when its QoS was read (monotonic)
        self._qos: dict[tuple[str, str, str], dict[str, Any]] = {}
        self._gids: dict[str, dict[bytes, str]] = {}  # topic -> publisher endpoint gid -> node

    def refresh(self, node: Node, topic: str, endpoints: frozenset[tuple[str, str]],
                nodes: dict[str, NodeReading], deadline: float) -> None:
        if self._known.get(topic) == endpoints or time.monotonic() > deadline:
            return
        self._read(node, topic, endpoints, nodes)

    def refresh_stale(self, node: Node, topics: dict[str, frozenset[tuple[str, str]]],
                      nodes: dict[str, NodeReading]) -> None:
        """Read again, oldest first, the topics whose QoS is older than ``every_s``, for at most
        ``stale_budget_s`` (one read at least, when one is due)."""
        now = time.monotonic()
        due = sorted((at, t) for t, at in self._read_at.items() if t in topics and now - at >= self.every_s)
        deadline = now + self.stale_budget_s
        for _, topic in due:
            self._read(node, topic, topics[topic], nodes)
            if time.monotonic() > deadline:
                break

    def _read(self, node: Node, topic: str, endpoints: frozenset[tuple[str, str]],
              nodes: dict[str, NodeReading]) -> None:
        gids: dict[bytes, str] = {}
        for role, call in (("pub", node.get_publishers_info_by_topic),
                           ("sub", node.get_subscriptions_info_by_topic)):
            for e in _endpoints(call(topic), topic, nodes):
                before = self._qos.get((topic, e.node, role))
                if before is not None and before != e.qos:
                    self.version += 1
                self._qos[(topic, e.node, role)] = e.qos
                if role == "pub":
                    gids[e.gid] = e.node
        self._gids[topic] = gids
        self._known[topic] = endpoints
        self._read_at[topic] = time.monotonic()

    def get(self, topic: str, node: str, role: str) -> dict[str, Any]:
        return self._qos.get((topic, node, role), {})

    def publisher_gids(self, topic: str) -> dict[bytes, str]:
        """Return the gid → node of ``topic``'s publishers, as last read."""
        return self._gids.get(topic, {})

    def invalidate(self, topics: set[str] | None = None) -> None:
        """Read these topics' endpoints again (None: all): a publisher gid we do not know came,
        or a process exited (a node back under its name has new gids, the same endpoint set)."""
        self._known = {} if topics is None else {t: v for t, v in self._known.items() if t not in topics}

    def forget(self, topics: set[str]) -> None:
        self._known = {t: v for t, v in self._known.items() if t in topics}
        self._read_at = {t: v for t, v in self._read_at.items() if t in topics}
        self._qos = {k: v for k, v in self._qos.items() if k[0] in topics}
        self._gids = {t: v for t, v in self._gids.items() if t in topics}


class GidCache:
    """Each node's /rosout publisher gid (what maps a node to its process), read only when due.

    A node without /rosout (``enable_rosout=False``, ``--disable-rosout-logs``) is known by its
    /parameter_events publisher, which every node has by default, read only while such a node is
    listed: any endpoint's gid starts with its participant's GUID prefix.

    ``get_publishers_info_by_topic`` scans every endpoint and rclpy builds a QoS object for each
    one found (a large part of a graph read: bench/bench_monitor_cpu.py, figures in docs/collector.md),
    for gids that change only when a node is created again. They are read when a node appears
    (and again each sample while one still has no gid, for ``settle_s`` after the node set
    changed: its endpoints are discovered after its name),
    after `invalidate` (the collector calls it when a process exits: a node restarted under the
    same name has a new gid), and at least every ``every_s``.
    """

    def __init__(self, every_s: float = 5.0, settle_s: float = 3.0) -> None:
        self.every_s, self.settle_s = every_s, settle_s
        self.reads = 0  # calls to the graph API so far (for tests and benchmarks)
        self._gids: dict[str, bytes] = {}
        self._prefixes: dict[str, set[bytes]] = {}  # node → GUID prefixes of its participants
        self._names: frozenset[str] = frozenset()
        self._read_at: float | None = None
        self._changed_at = 0.0

    def invalidate(self) -> None:
        """Read the gids again on the next call."""
        self._read_at = None

    def get(self, node: Node, nodes: dict[str, NodeReading], now: float) -> dict[str, bytes]:
        """Return node fqn → gid for ``nodes`` (those whose gid is known), read again when due."""
        names = frozenset(nodes)
        if names != self._names:
            self._names, self._changed_at = names, now
        missing = not names <= self._gids.keys()
        if (self._read_at is None or now - self._read_at >= self.every_s
                or (missing and now - self._changed_at < self.settle_s)):
            self._gids, self._prefixes = {}, {}
            for topic in ("/rosout", "/parameter_events"):
                for ep in _endpoints(node.get_publishers_info_by_topic(topic), topic, nodes):
                    self._gids.setdefault(ep.node, ep.gid)
                    self._prefixes.setdefault(ep.node, set()).add(ep.gid[:12])
                self.reads += 1
                if names <= self._gids.keys():
                    break
            self._read_at = now
        return {n: g for n, g in self._gids.items() if n in names}

    def participants(self) -> dict[str, int]:
        """Node → how many participants publish its /rosout (or /parameter_events), as last read."""
        return {n: len(p) for n, p in self._prefixes.items()}


@dataclass
class GraphStructure:
    """What the per-node queries found: the nodes with their services and clients, each topic's
    types and its publishing and subscribing nodes (``ends``: topic -> (publishers, subscribers),
    sorted; ``keys``: topic -> its endpoint set), what a node publishes that is not a topic of the
    model (service events, goal status and feedback), the nodes skipped, and the ghosts left out
    (`read_structure`). Read-only once read."""

    nodes: dict[str, NodeReading] = field(default_factory=dict)
    topics: dict[str, list[str]] = field(default_factory=dict)
    ends: dict[str, tuple[list[str], list[str]]] = field(default_factory=dict)
    keys: dict[str, frozenset[tuple[str, str]]] = field(default_factory=dict)
    service_events: dict[str, str] = field(default_factory=dict)
    goal_status: dict[str, list[str]] = field(default_factory=dict)
    goal_feedback: dict[str, str] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)
    ghosts: list[str] = field(default_factory=list)


class StructureCache:
    """The graph's structure, read again only when the graph changed (``signal``: a `GraphSignal`;
    None: every call), when the last read skipped a node, and at least every ``every_s``."""

    def __init__(self, signal: GraphSignal | None = None, every_s: float = 5.0) -> None:
        self.signal, self.every_s = signal, every_s
        self.reads = self.reuses = 0  # for tests and benchmarks
        self._last: GraphStructure | None = None
        self._key: tuple[str, bool, bool] | None = None
        self._at = -float("inf")
        self._had: set[str] = set()  # nodes seen with an endpoint: one listed without any is a ghost

    def invalidate(self) -> None:
        """Read the structure again on the next call."""
        self._last = None

    def get(self, node: Node, key: tuple[str, bool, bool], now: float) -> GraphStructure:
        """Return the structure for ``key`` (own name, include_hidden, include_internal)."""
        # Asked first: a change during the read below triggers again, for the next call.
        changed = self.signal is None or self.signal.changed()
        last = self._last
        if changed or last is None or last.skipped or key != self._key or now - self._at >= self.every_s:
            self._last, self._key, self._at = read_structure(node, *key, had=self._had), key, now
            self.reads += 1
        else:
            self.reuses += 1
        return self._last


def read_structure(node: Node, own: str, include_hidden: bool = False,
                   include_internal: bool = False, had: set[str] | None = None) -> GraphStructure:
    """Return the graph's structure: one listing of the nodes, then each node's publishers,
    subscriptions, services and clients (`read_graph` has the other parameters).

    ``had`` holds the nodes seen with an endpoint in earlier reads (added to here). A node listed
    again without any is left out, in ``ghosts``: its participant ended, and a discovery-info
    sample that came after the participant's removal left its name in the graph cache, where it
    stays (the endpoints went with the participant). A node's name is discovered before its
    endpoints, so one never seen with any is kept.
    """
    r = GraphStructure()
    for name, ns in node.get_node_names_and_namespaces():
        fqn = node_fqn(ns, name)
        if fqn == own or name == UNKNOWN_NODE or not _keep(fqn, include_hidden):
            continue
        if fqn in r.nodes:  # one name, several nodes: one member, counted (graph_anomalies alerts)
            r.nodes[fqn].instances += 1
            continue
        r.nodes[fqn] = NodeReading(fqn, name, ns)
    def topic_ok(t: str) -> bool:
        return _keep(t, include_hidden) and (include_internal or t not in INFRA_TOPICS)
    ends: dict[str, dict[str, list[str]]] = {"pub": {}, "sub": {}}
    for fqn, nr in list(r.nodes.items()):
        try:
            servers = node.get_service_names_and_types_by_node(nr.name, nr.namespace)
            clients = node.get_client_names_and_types_by_node(nr.name, nr.namespace)
            pubs = node.get_publisher_names_and_types_by_node(nr.name, nr.namespace)
            subs = node.get_subscriber_names_and_types_by_node(nr.name, nr.namespace)
        except NodeNameNonExistentError:
            # Vanished between the listing and this query: skip it for this sample.
            r.skipped[fqn] = "node vanished during the graph read"
            del r.nodes[fqn]
            continue
        if had is not None:
            if servers or clients or pubs or subs:
                had.add(fqn)
            elif fqn in had:
                r.ghosts.append(fqn)
                del r.nodes[fqn]
                continue
        nr.action_servers = {a: t for a, t in _actions(servers).items() if _keep(a, include_hidden)}
        nr.action_clients = {a: t for a, t in _actions(clients).items() if _keep(a, include_hidden)}
        for src, dst in ((servers, nr.services), (clients, nr.clients)):
            for sname, types in src:
                if not _keep(sname, include_hidden):
                    continue
                if not include_internal and is_param_service(sname, fqn):
                    continue
                dst[sname] = list(types)
        for role, lst in (("pub", pubs), ("sub", subs)):
            for topic, types in lst:
                if topic_ok(topic):
                    ends[role].setdefault(topic, []).append(fqn)
                    r.topics.setdefault(topic, list(types))
                elif role == "pub" and topic.endswith(EVENT_SUFFIX) and types:
                    # service introspection: observed whether or not hidden names are kept
                    r.service_events.setdefault(topic[: -len(EVENT_SUFFIX)], types[0])
                elif role == "pub" and topic.endswith(STATUS_SUFFIX) and GOAL_STATUS_TYPE in types:
                    r.goal_status.setdefault(topic, []).append(fqn)  # an action server's goals
                elif role == "pub" and topic.endswith(FEEDBACK_SUFFIX) and types:
                    r.goal_feedback.setdefault(topic, types[0])  # their progress
    for topic in sorted(r.topics):
        pubs_, subs_ = sorted(set(ends["pub"].get(topic, []))), sorted(set(ends["sub"].get(topic, [])))
        r.keys[topic] = frozenset([(n, "pub") for n in pubs_] + [(n, "sub") for n in subs_])
        r.ends[topic] = (pubs_, subs_)
    return r


def read_graph(node: Node, *, own: str, include_hidden: bool = False,
               include_internal: bool = False, qos: QosCache | None = None,
               gids: GidCache | None = None, structure: StructureCache | None = None) -> GraphReading:
    """Return the ROS graph as node ``node`` sees it now.

    Parameters
    ----------
    node : rclpy Node
        The observer node (its graph cache is read; it is never spun).
    own : str
        Fully qualified name of the observer node itself, left out of everything.
    include_hidden : bool
        Keep hidden nodes, topics and services (``_`` names, action internals).
    include_internal : bool
        Keep parameter services, ``/rosout`` and ``/parameter_events``.
    qos : QosCache, optional
        Where endpoint QoS is kept between samples (a fresh one reads every topic's QoS).
    gids : GidCache, optional
        Where the nodes' /rosout gids are kept between samples (a fresh one reads them).
    structure : StructureCache, optional
        Where the structure is kept between samples (a fresh one reads it).
    """
    qos = qos or QosCache(budget_s=float("inf"))
    gids = gids or GidCache()
    s = (structure or StructureCache()).get(node, (own, include_hidden, include_internal), time.monotonic())
    # Fresh containers each sample: the structure is shared between the samples that reuse it.
    r = GraphReading(nodes=dict(s.nodes), topics=dict(s.topics), service_events=dict(s.service_events),
                     goal_status={t: list(v) for t, v in s.goal_status.items()},
                     goal_feedback=dict(s.goal_feedback), skipped=dict(s.skipped))
    deadline = time.monotonic() + qos.budget_s
    for topic, key in s.keys.items():
        qos.refresh(node, topic, key, r.nodes, deadline)
    qos.refresh_stale(node, s.keys, r.nodes)
    for topic, (pubs_, subs_) in s.ends.items():
        t0 = r.topics[topic][0] if r.topics[topic] else ""
        r.publishers[topic] = [Endpoint(n, topic, t0, b"", qos.get(topic, n, "pub")) for n in pubs_]
        r.subscribers[topic] = [Endpoint(n, topic, t0, b"", qos.get(topic, n, "sub")) for n in subs_]
        r.publisher_gids[topic] = qos.publisher_gids(topic)
    qos.forget(set(r.topics))
    r.rosout_gids = gids.get(node, r.nodes, time.monotonic())
    r.participants = gids.participants()
    r.qos_version = qos.version
    return r


def _endpoints(infos: list[Any], topic: str, nodes: dict[str, NodeReading]) -> list[Endpoint]:
    out = []
    for i in infos:
        if i.node_name == UNKNOWN_NODE:  # name not discovered yet (~0.1 s): no phantom member
            continue
        fqn = node_fqn(i.node_namespace, i.node_name)
        if fqn not in nodes:  # our own node, a hidden one, or one that came after the listing
            continue
        out.append(Endpoint(fqn, topic, i.topic_type, bytes(i.endpoint_gid), qos_dict(i.qos_profile)))
    return out
