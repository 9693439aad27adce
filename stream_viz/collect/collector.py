"""The collector: fills the model live from a real ROS 2 system and the OS, one `Sample` per call.

It only observes: an own rclpy Context and node (no /rosout publisher, no parameter services),
graph API calls, raw subscriptions; it never publishes on or calls the system's topics/services.
"""

from __future__ import annotations

import os
import socket
import time
from collections.abc import MutableMapping
from typing import Any

import networkx as nx
import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.type_description_service import START_TYPE_DESCRIPTION_SERVICE_PARAM

from stream_viz.collect.build import build_model
from stream_viz.collect.cgroups import read_mounts
from stream_viz.collect.diagnostics import DiagnosticsReader
from stream_viz.collect.exitcodes import ExitCodes, describe_exit, note_exit_code
from stream_viz.collect.fastdds import decode_gid
from stream_viz.collect.goals import STATUS_SUFFIX, GoalTracker
from stream_viz.collect.graphsignal import GraphSignal
from stream_viz.collect.hosts import HostReports
from stream_viz.collect.last_words import LAST_WORDS_S, last_words, newest_lines, note_lines
from stream_viz.collect.naming import NodeNames, recently_left
from stream_viz.collect.oomkills import OomKill, OomWatch
from stream_viz.collect.params import param_event
from stream_viz.collect.pidmap import PidResolver
from stream_viz.collect.processes import ProcessSampler
from stream_viz.collect.readings import GraphReading, PidInfo, ProcessReading, TopicStats
from stream_viz.collect.rosgraph import GidCache, QosCache, StructureCache, read_graph
from stream_viz.collect.services import ServiceCalls, ServiceStats, party
from stream_viz.collect.topics import DIAGNOSTICS, TopicMonitor, log_event
from stream_viz.collect.undiscovered import UndiscoveredWatch, explain, explain_late
from stream_viz.errors import CollectError
from stream_viz.model.diff import diff
from stream_viz.model.graph import new_graph
from stream_viz.model.ids import make_id, node_fqn
from stream_viz.records import Event, Sample

__all__ = ["Collector", "ObserverNode", "build_model", "end_node", "new_node"]

# A node that left this long before its process's end left with it (rclpy sends the goodbye,
# then the interpreter exits): the process's exit event names it.
EXIT_AFTER_LEFT_S = 3.0
EXIT_RECHECK_S = 0.25  # after a process ended with its nodes listed: a clean goodbye arrives by then


class _NoPublisher:
    """Stands in for rclpy's ``/parameter_events`` publisher: the events of our own parameters
    (declared by rclpy itself at start-up) are dropped instead of published on the system's topic."""

    def publish(self, msg: object) -> None:
        pass


class ObserverNode(Node):
    """An rclpy node that can only subscribe and read the graph.

    A plain rclpy Node always holds a ``/parameter_events`` publisher (and publishes on it while
    it declares ``use_sim_time``) and serves ``~/get_type_description``; an observer must do
    neither. No /rosout publisher, no parameter or logger services either.
    """

    def __init__(self, name: str, *, context: Context) -> None:
        super().__init__(name, context=context, enable_rosout=False, start_parameter_services=False,
                         parameter_overrides=[Parameter(START_TYPE_DESCRIPTION_SERVICE_PARAM, value=False)])

    def create_publisher(self, msg_type: Any, topic: str, *args: Any, **kwargs: Any) -> Any:
        if topic == "/parameter_events" and not hasattr(self, "_type_description_service"):
            return _NoPublisher()  # rclpy's own, asked for while the node is being constructed
        raise CollectError(f"the observer node never publishes (asked to publish on {topic})")


def observe_as_super_client(environ: MutableMapping[str, str]) -> bool:
    """Set ``ROS_SUPER_CLIENT`` in ``environ`` where a Fast DDS discovery server is used and the
    user left it unset; return whether the graph can be seen whole.

    A plain client of a discovery server learns only the endpoints that match its own: the graph
    would show the nodes but not the topics this observer does not subscribe. Fast DDS reads the
    variable when a participant is created, as ``ros2`` CLI users set it. False: the user chose a
    plain client.
    """
    if not environ.get("ROS_DISCOVERY_SERVER", "").strip():
        return True
    value = environ.setdefault("ROS_SUPER_CLIENT", "TRUE")
    return value.strip().lower() in ("true", "1")


def new_node(cls: type[Node], name: str, domain_id: int) -> tuple[Context, Node]:
    """Return a Context of our own on ``domain_id`` (nothing global touched but, with a discovery
    server, ``ROS_SUPER_CLIENT``: `observe_as_super_client`) and a node of it."""
    observe_as_super_client(os.environ)
    ctx = Context()
    rclpy.init(args=[], context=ctx, domain_id=domain_id)
    try:
        return ctx, cls(name, context=ctx)
    except BaseException:
        ctx.try_shutdown()
        raise


def end_node(node: Node | None, ctx: Context | None) -> None:
    """Destroy ``node`` and shut its own Context (either may be None)."""
    try:
        if node is not None:
            node.destroy_node()
    finally:
        if ctx is not None:
            ctx.try_shutdown()


class Collector:
    """Watches one ROS 2 domain.

    Parameters
    ----------
    domain_id : int or None
        The ROS_DOMAIN_ID to observe (None: the environment's, else 0).
    include_hidden : bool
        Keep hidden names (``_…``, action internals) in the model.
    include_internal : bool
        Keep parameter services, ``/rosout`` and ``/parameter_events`` in the model.
    topic_metrics : bool
        Subscribe to every topic for rate/jitter/latency/bandwidth/drops.
    window_s : float
        Sliding window of the topic metrics.
    """

    def __init__(self, domain_id: int | None = None, *, include_hidden: bool = False,
                 include_internal: bool = False, topic_metrics: bool = True, window_s: float = 3.0) -> None:
        if domain_id is None:
            try:
                domain_id = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
            except ValueError as e:
                raise CollectError(f"ROS_DOMAIN_ID={os.environ['ROS_DOMAIN_ID']!r} is not an integer") from e
        self.domain_id = domain_id
        self.include_hidden, self.include_internal = include_hidden, include_internal
        self.topic_metrics, self.window_s = topic_metrics, window_s
        self.name = f"_stream_viz_observer_{os.getpid()}"
        self.own = node_fqn("/", self.name)
        self._ctx: Context | None = None
        self.node = None
        self.topics: TopicMonitor | None = None
        self.resolver: PidResolver | None = None
        self.hosts: HostReports | None = None
        self.exits: ExitCodes | None = None
        self.sampler = ProcessSampler()
        self.ooms = OomWatch(read_mounts())
        self.qos = QosCache()
        self.gids = GidCache()
        self.structure = StructureCache()  # without a graph change signal until start()
        self.diagnostics = DiagnosticsReader()
        self.goals = GoalTracker()
        self.calls = ServiceCalls(window_s=window_s)
        self.undiscovered = UndiscoveredWatch(domain_id)
        self._prev = new_graph()
        self._prev_pids: dict[str, int | None] = {}
        self._prev_t: float | None = None  # the last sample's time
        self._lines: dict[str, tuple[float, str]] = {}  # /rosout logger → its newest line (`last_words`)
        self._left: dict[str, float] = {}  # node fqn → when it left the graph
        self._param_values: dict[tuple[str, str], str] = {}  # (node fqn, parameter) → its value
        self._left_pids: dict[str, int | None] = {}  # node fqn in `_left` → the process it was in
        self._dead: dict[int, ProcessReading] = {}
        self._closed = False
        self._whole_graph = True  # False: a plain client of a discovery server (the user's choice)

    def start(self) -> None:
        """Create our own rclpy Context and observer node, subscribe to the event topics."""
        if self.node is not None:
            return
        try:
            self._ctx, self.node = new_node(ObserverNode, self.name, self.domain_id)
        except Exception as e:  # rclpy raises RCLError/RuntimeError kinds we cannot name portably
            self.close()
            raise CollectError(f"cannot start the ROS 2 observer on domain {self.domain_id}: {e}") from e
        self.structure = StructureCache(GraphSignal(self.node))
        self._whole_graph = observe_as_super_client(os.environ)  # as new_node set it up
        self.topics = TopicMonitor(self.node, self.window_s, metrics=self.topic_metrics)
        self.topics.start()
        self.resolver = PidResolver(self.domain_id, self._own_host())
        self.hosts = HostReports(self.node, (self.resolver.own_host, socket.gethostname()))
        self.exits = ExitCodes()

    def _own_host(self) -> int | None:
        # Our own /rosout subscription carries our participant's prefix, hence this host's id.
        for i in self.node.get_subscriptions_info_by_topic("/rosout"):
            if node_fqn(i.node_namespace, i.node_name) == self.own:
                info = decode_gid(bytes(i.endpoint_gid))
                return info.host_id if info else None
        return None

    def sample(self) -> Sample:
        """Read everything now and return the model with θ, the events since last time, the diff."""
        if self.node is None:
            raise CollectError("Collector.sample() called before start() (or after close())")
        t = time.time()
        reading = read_graph(self.node, own=self.own, include_hidden=self.include_hidden,
                             include_internal=self.include_internal, qos=self.qos, gids=self.gids,
                             structure=self.structure)
        self.topics.update(reading.topics, reading.service_events, reading.goal_status, reading.goal_feedback)
        self.goals.forget(set(reading.goal_status))
        pids = self.resolver.resolve(reading.rosout_gids)
        for fqn in reading.nodes:
            pids.setdefault(fqn, PidInfo(None, "unknown"))
        node_pids = {n: p.pid for n, p in pids.items() if n in reading.nodes}
        ps = self.sampler.sample({p for p in node_pids.values() if p is not None})
        ooms = self.ooms.update(ps.processes, {p: r.metrics.get("rss_mb", 0.0) for p, r in ps.exited.items()})
        if ps.exited:  # one of its nodes may be back under the same name, with new gids
            self.gids.invalidate()
            self.qos.invalidate()
            self.structure.invalidate()
        events = self._process_events(t, ps.exited, node_pids, ooms)
        events += self._restarts(t, node_pids)
        # Keep the process of nodes DDS still lists after their process died (SIGKILL: ~20 s).
        self._dead.update(ps.exited)
        listed = set(node_pids.values())
        self._dead = {p: r for p, r in self._dead.items() if p in listed and p not in ps.processes}
        processes = dict(ps.processes)
        for pid, r in self._dead.items():
            r.alive = False
            processes[pid] = r
        for pid in set(node_pids.values()) - set(processes) - {None}:
            # Dead before we ever read it: a node of a process that is not there any more.
            processes[pid] = ProcessReading(pid, None, alive=False)
        pub_counts = {tp: len(eps) for tp, eps in reading.publishers.items()}
        stats = self.topics.stats(pub_counts)
        events += stamp_reset_events(stats)
        # A message from a publisher gid we do not know: a new endpoint of an unchanged node set.
        self.qos.invalidate({tp for tp, st in stats.items()
                             if any(g not in reading.publisher_gids.get(tp, {}) for g in st.by_publisher)})
        # An aggregator's "r2_localizer: ERROR" after the crash is about the node that left.
        self._left = recently_left(self._left, self._prev_pids, reading.nodes, t)
        self._left_pids = {n: self._left_pids.get(n, self._prev_pids.get(n)) for n in self._left}
        index = NodeNames(reading.nodes, self._left)
        # Taken after `stats` drained the topics: a crash's last line may have come just now.
        messages = self.topics.take_messages()
        note_lines(self._lines, (msg for topic, msg, _, _ in messages if topic == "/rosout"))
        self._last_words(t, events)
        events += self._message_events(t, reading, index, messages)
        services, calls = self._service_calls(reading)
        G = build_model(reading, pids, processes, stats, services, calls)
        for fqn, at in newest_lines(self._lines, reading.nodes).items():
            if (m := make_id("node", fqn)) in G:
                G.nodes[m]["logged_at"] = at  # any level: who ran last on a stalled executor (`siblings`)
        self._goal_progress(G, t, reading, stats)
        unreadable = {make_id("node", n): why for n, why in reading.skipped.items()}
        remote_events, unreadable_remote = self.hosts.apply(G, pids, t)  # other computers' agents
        events += remote_events
        unreadable.update(unreadable_remote)
        for pid, why in ps.errors.items():
            if pid not in processes:  # dead ones are in the model, marked alive=False
                unreadable[make_id("process", pid)] = why
        for pid, r in ps.processes.items():
            if r.unreadable:
                unreadable[make_id("process", pid)] = "access denied: " + ", ".join(r.unreadable)
        for tp, st in stats.items():
            if not st.measured and tp in reading.topics:
                unreadable[make_id("topic", tp)] = st.reason
        d = diff(self._prev, G)
        self._prev, self._prev_pids, self._prev_t = G, node_pids, t
        live = {p.prefix for p in pids.values() if p.prefix}
        self.resolver.forget(live)
        self.undiscovered.update(self._participant_gids, self.resolver.own_host, t)
        return Sample(t, G, events, d, unreadable)

    def _process_events(self, t: float, exited: dict[int, ProcessReading],
                        node_pids: dict[str, int | None], ooms: dict[int, OomKill]) -> list[Event]:
        out = []
        listed_at_read = {n for n, p in node_pids.items() if p in exited}
        still = self._still_listed(listed_at_read) if listed_at_read else set()
        for pid, r in sorted(exited.items()):
            # A process that outlived its nodes' goodbye past a sample (a slow interpreter exit)
            # had them still: those that left within `EXIT_AFTER_LEFT_S`.
            had = sorted({n for n, p in self._prev_pids.items() if p == pid}
                         | {n for n, p in self._left_pids.items()
                            if p == pid and t - self._left[n] <= EXIT_AFTER_LEFT_S})
            listed = sorted(n for n in had if node_pids.get(n) == pid and n in still)
            # Nodes still in the DDS graph after their process ended: it did not shut down cleanly.
            level = "error" if listed else ("warn" if had else "info")
            nodes = [make_id("node", n) for n in had]
            data = {"pid": pid, "process": make_id("process", pid), "nodes": nodes, "name": r.name,
                    "still_listed": [make_id("node", n) for n in listed]}
            code, ended = self.exits.take_exit(pid) if self.exits is not None else (None, None)
            level = note_exit_code(code, level, bool(listed), data)
            if ended is not None:
                data["ended_at"] = ended
            text = (f"process {pid} ({r.name}) {describe_exit(code)}"
                    + (f" with nodes {', '.join(had)}" if had else ""))
            if (oom := ooms.get(pid)) is not None:
                level, text, data = oom.said(text, data)
            for m in [*nodes, make_id("process", pid)]:
                out.append(Event(t, "exit", m, level, text, data))
        return out

    def _last_words(self, t: float, events: list[Event]) -> None:
        """Put in each exit event of processes with nodes its last words (`last_words`): before
        the kernel's exit time where known, else since the last sample."""
        for e in events:
            data = e.data
            if e.kind != "exit" or not data.get("nodes") or e.member != data.get("process"):
                continue
            ended = data.get("ended_at")
            start = ended if ended is not None else (self._prev_t or t)
            fqns = [n.removeprefix("node:") for n in data["nodes"]]
            if said := last_words(self._lines, fqns, start - LAST_WORDS_S, t if ended is None else ended):
                data["last_words"] = {"node": make_id("node", said[0]), "t": said[1], "text": said[2]}

    def _still_listed(self, names: set[str]) -> set[str]:
        """Return those of ``names`` that DDS still lists a moment after their process ended.

        The graph is read before the processes are: a process that destroyed its nodes and ended
        in between (or whose goodbye was still on its way) is seen ended with its nodes listed, as
        a killed one is. A killed process's nodes stay listed until their lease ends (seconds); a
        clean one's are gone a moment later."""
        time.sleep(EXIT_RECHECK_S)
        try:
            now = {node_fqn(ns, n) for n, ns in self.node.get_node_names_and_namespaces()}
        except Exception:  # the graph unreadable now: keep what the read said
            return names
        return names & now

    def _restarts(self, t: float, node_pids: dict[str, int | None]) -> list[Event]:
        out = []
        for n, pid in sorted(node_pids.items()):
            old = self._prev_pids.get(n)
            if old is not None and pid is not None and old != pid:
                out.append(Event(t, "restart", make_id("node", n), "warn",
                                 f"node {n} now runs in process {pid} (was {old})",
                                 {"old_pid": old, "pid": pid}))
        return out

    def _message_events(self, t: float, reading: GraphReading, index: NodeNames,
                        messages: list[tuple[str, Any, int, bytes | None]]) -> list[Event]:
        services = frozenset(s for nr in reading.nodes.values() for s in (*nr.services, *nr.clients))
        actions = frozenset(a for nr in reading.nodes.values()
                            for a in (*nr.action_servers, *nr.action_clients))
        out: list[Event] = []
        for topic, msg, recv, gid in messages:
            try:
                if topic == "/rosout":
                    ev = log_event(msg, index, services, actions)
                    if ev is not None:
                        out.append(ev)
                elif topic == "/parameter_events":
                    self.diagnostics.hardware.add(msg)
                    ev = param_event(msg, recv / 1e9, self._param_values)
                    if ev is not None:
                        out.append(ev)
                elif topic in DIAGNOSTICS:
                    publisher = self._publisher(reading, topic, gid)
                    out += self.diagnostics.events(topic, msg, recv / 1e9, publisher, index)
                elif topic in reading.goal_status:
                    out += self.goals.events(topic, msg, recv, reading.goal_status[topic])
            except (AttributeError, TypeError, ValueError) as e:  # a malformed message: say so, go on
                out.append(Event(t, "observe_error", make_id("topic", topic), "warn",
                                 f"cannot read a {topic} message: {e}"))
        return out

    def _goal_progress(self, G: nx.MultiDiGraph, t: float, reading: GraphReading,
                       stats: dict[str, TopicStats]) -> None:
        """Put on each action member since when a goal has been executing and when its newest
        feedback came (``executing_since``, ``feedback_at``: s, None when not / never)."""
        for topic in reading.goal_feedback:
            st = stats.get(topic)
            if st is not None and st.measured and "age_s" in st.metrics:
                self.goals.fed(topic, t - st.metrics["age_s"])
        for topic in reading.goal_status:
            action = topic.removesuffix(STATUS_SUFFIX)
            member = make_id("action", action)
            if member in G:
                G.nodes[member].update(executing_since=self.goals.executing_since.get(action),
                                       feedback_at=self.goals.feedback.get(action))

    @staticmethod
    def _publisher(reading: GraphReading, topic: str, gid: bytes | None) -> str | None:
        """The node that published a message: by its gid, else the topic's only publisher."""
        if gid is not None and gid in reading.publisher_gids.get(topic, {}):
            return reading.publisher_gids[topic][gid]
        pubs = {e.node for e in reading.publishers.get(topic, [])}
        return next(iter(pubs)) if len(pubs) == 1 else None

    def _service_calls(self, reading: GraphReading) -> tuple[dict[str, ServiceStats],
                                                            dict[str, list[dict[str, object]]]]:
        """Feed the service events taken since the last sample; return the services' stats and
        their open calls with the client and server nodes where the gids tell them."""
        for service, recv, (etype, _stamp, client_gid, seq), writer in self.topics.take_service_events():
            self.calls.add(service, recv, etype, client_gid, seq, writer)
        self.calls.forget(set(reading.service_events))
        stats = self.calls.stats(time.time_ns())
        if not stats:  # no service introspected: nothing to attribute
            return {}, {}
        prefixes: dict[bytes, list[str]] = {}
        for node, gid in reading.rosout_gids.items():
            prefixes.setdefault(gid[:12], []).append(node)
        servers: dict[str, list[str]] = {}
        clients: dict[str, list[str]] = {}
        for fqn, nr in reading.nodes.items():
            for s in nr.services:
                servers.setdefault(s, []).append(fqn)
            for s in nr.clients:
                clients.setdefault(s, []).append(fqn)
        calls = {}
        for service, st in stats.items():
            calls[service] = [
                {"client": _node_id(party(cg, prefixes, sorted(clients.get(service, [])))),
                 "server": _node_id(party(sg, prefixes, sorted(servers.get(service, [])))),
                 "waited_s": round(waited, 3)}
                for waited, cg, sg in st.open_calls[:10]]
        return stats, calls

    def _participant_gids(self) -> list[bytes]:
        # Every node, hidden ones too, publishes /rosout or /parameter_events; an observer like
        # ours has neither but subscribes to /rosout.
        eps = [*self.node.get_publishers_info_by_topic("/rosout"),
               *self.node.get_publishers_info_by_topic("/parameter_events"),
               *self.node.get_subscriptions_info_by_topic("/rosout")]
        return [bytes(e.endpoint_gid) for e in eps]

    def limits(self) -> dict[str, str]:
        """What this collector cannot do on this system, and why (empty when it does it all).

        Each is a fallback the samples go on with: the graph read in full every sample (no graph
        change signal), topics taken through rclpy without their publishers' gids (a topic's
        rate and age are not split per publisher, so all its publishers share its symptoms). And
        each local process on our domain that was never discovered (`collect.undiscovered`): its
        nodes are missing from the model.
        """
        out: dict[str, str] = {}
        signal = self.structure.signal
        if signal is not None and not signal.available:
            out["graph change signal"] = f"{signal.why}; the graph is read in full every sample"
        if not self._whole_graph:
            out["whole graph"] = ("ROS_SUPER_CLIENT is false with a discovery server: only the endpoints "
                                  "this observer matches are discovered")
        rcl = self.topics.rcl if self.topics is not None else None
        if rcl is not None and not rcl.available:
            out["publisher gids"] = (f"{rcl.why}; a topic's rate and message age are not split per "
                                     "publisher")
        for p in self.undiscovered.found:
            out[f"discovery of process {p.pid}"] = explain(p, self.domain_id, os.environ,
                                                           self.undiscovered.grace_s)
        return out

    def retracted(self) -> dict[str, str]:
        """The limits said before that turned out not to hold, and why (keys as in `limits`): a
        process named undiscovered whose nodes were discovered later."""
        return {f"discovery of process {pid}": explain_late(p, t)
                for pid, (p, t) in self.undiscovered.late.items()}

    def close(self) -> None:
        """Stop observing: end the drain thread, destroy the node, shut our own Context. Idempotent."""
        if self._closed:
            return
        self._closed = True
        if self.topics is not None:
            self.topics.close()
        if self.structure.signal is not None:
            self.structure.signal.close()
        if self.exits is not None:
            self.exits.close()
        node, ctx, self.node, self._ctx = self.node, self._ctx, None, None
        end_node(node, ctx)

    def __enter__(self) -> Collector:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def stamp_reset_events(stats: dict[str, TopicStats]) -> list[Event]:
    """One ``stamp_reset`` event per topic whose header stamps went back since the last sample."""
    out = []
    for topic, st in sorted((tp, st) for tp, st in stats.items() if st.stamp_resets):
        recv, back = max(st.stamp_resets, key=lambda r: r[1])
        out.append(Event(recv / 1e9, "stamp_reset", make_id("topic", topic), "info",
                         f"header stamps went back {back / 1e9:.1f} s: the stream restarted its time "
                         "(a recording looped, a simulation reset)",
                         {"back_s": back / 1e9, "resets": len(st.stamp_resets)}))
    return out


def _node_id(fqn: str | None) -> str | None:
    return None if fqn is None else make_id("node", fqn)
