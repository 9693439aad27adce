"""Topic metrics from raw subscriptions drained without an executor, plus the event topics.

A background thread takes every waiting message (no callbacks, no deserialisation) and keeps
``(received, source timestamp, size, sequence number, publisher gid, message age)`` per topic
over a sliding window with running sums (`TopicWindow`). Inter-arrival times stay exact: they
come from the ``received_timestamp`` DDS stamps, not from when we drained. Messages are taken
through rcl with their publisher's gid (`stream_viz.collect.rcltake`; through rclpy without it
where that is unavailable); a type that begins with a ``std_msgs/Header`` has its stamp read from
the serialized bytes (`stream_viz.collect.cdr`). /rosout and /parameter_events are deserialised,
/diagnostics and /diagnostics_agg deserialised from the bytes taken (for events), service event
topics read raw (`take_service_events`). The QoS (best effort, volatile) matches any publisher.
"""

from __future__ import annotations

import importlib
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message

from stream_viz.collect.cdr import has_header, header_stamp_ns, is_service_event, service_event_info
from stream_viz.collect.goals import GOAL_STATUS_TYPE, STATUS_SUFFIX
from stream_viz.collect.naming import NodeNames, named_in_text
from stream_viz.collect.rcltake import RclTake
from stream_viz.collect.readings import TopicStats
from stream_viz.collect.services import EVENT_SUFFIX
from stream_viz.collect.simclock import CLOCK_TYPE, ROS_CLOCK, SimClock
from stream_viz.collect.stamp_partners import COMPARED, PAIR_SHARE, stamp_partners
from stream_viz.collect.window import TopicWindow
from stream_viz.records import Event

OBSERVE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
# An action's status array is sent on change, reliable and transient-local (rcl_action's default):
# read the same way, a goal already executing when we looked is listed at once, so its end is
# seen as a change (`goals`), where a volatile reader's first array is that end, undated.
STATUS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)
CLOCK_GRACE_NS = 2_000_000_000  # after /clock is subscribed, how long its first tick is awaited
PACE_SPAN_NS = 1_000_000_000  # the simulation's pace over the last second: as prompt as a recent rate
FIRST_LOOK_NS = 5_000_000_000  # from the start, how long a /clock not discovered yet is awaited
NO_RAW = frozenset({"/rosout", "/parameter_events"})  # busy infrastructure topics: no metrics
# Deserialised by rclpy: the log and the parameter events.
LOGS = {"/rosout": "rcl_interfaces/msg/Log", "/parameter_events": "rcl_interfaces/msg/ParameterEvent"}
DIAG_TYPE = "diagnostic_msgs/msg/DiagnosticArray"
DIAGNOSTICS = frozenset({"/diagnostics", "/diagnostics_agg"})  # taken whole and deserialised

# (received ns, source ns, size, sequence number, publisher gid or None, head or payload bytes)
Sink = Callable[[int, int, int, int, "bytes | None", bytes], None]


def import_type(type_name: str) -> type:
    """Import a message class from ``pkg/msg/Name`` (or an action's ``pkg/action/Name_FeedbackMessage``,
    which rosidl puts under ``Name.Impl``); raises ImportError / AttributeError naming it."""
    pkg, _, name = type_name.rpartition("/")
    module = importlib.import_module(pkg.replace("/", "."))
    if not hasattr(module, name) and "_" in name:
        base, _, part = name.rpartition("_")
        return getattr(getattr(module, base).Impl, part)
    return getattr(module, name)


@dataclass
class _Watch:
    sub: Any
    created_ns: int
    window: TopicWindow
    kind: str  # raw (metrics) | log (rclpy deserialises) | diag (payload kept) | event (service events)
    stamped: bool  # the type begins with a Header: the message age is read
    sink: Sink | None  # what the messages of the log, diag and event kinds go to


class TopicMonitor:
    """Raw subscriptions on the observed topics and a thread that drains them.

    Parameters
    ----------
    node : rclpy Node
        Our observer node (only subscriptions are created on it; nothing is published).
    window_s : float
        Length of the sliding window metrics are computed over.
    metrics : bool
        Subscribe to every topic for metrics; False keeps only the event topics (/rosout,
        /parameter_events, /diagnostics, /diagnostics_agg, service events).
    period_s : float
        Longest time between two drains of the thread. It drains more often when a topic is fast
        enough to fill a quarter of the queue (``OBSERVE_QOS.depth``) in that time; `stats` drains
        first, so the metrics are up to date whatever the period. Draining costs a wake-up per
        call: a calm system is drained rarely (the receive stamps are the middleware's, taken on
        arrival, so a late drain costs no accuracy; only the queue bounds the period).
    min_period_s : float
        Shortest time between two drains (a very fast topic).
    gids : bool
        Take through rcl with the publisher gids (`RclTake`); False: through rclpy, without.
    """

    def __init__(self, node: Node, window_s: float = 3.0, metrics: bool = True,
                 period_s: float = 1.0, min_period_s: float = 0.02, gids: bool = True) -> None:
        self.node, self.window_ns, self.metrics = node, int(window_s * 1e9), metrics
        self.max_period_s, self.min_period_s = period_s, min_period_s
        self.period_s = period_s  # the current one, adapted to the fastest topic
        self._last_drain = time.monotonic()
        self._lock = threading.Lock()
        self._watches: dict[str, _Watch] = {}
        self._failed: dict[str, str] = {}  # topic -> why it is not measured
        self._types: dict[str, str] = {}
        self._messages: list[tuple[str, Any, int, bytes | None]] = []  # (topic, msg or payload, recv, gid)
        self._service_events: list[tuple[str, int, tuple[int, int, bytes, int], bytes | None]] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.rcl = RclTake(rclpy.get_rmw_implementation_identifier()) if gids else None
        self.taken = 0  # messages taken so far (for the benchmark)
        self.clock = SimClock()  # simulated time, when the system publishes /clock
        self._stamp_pairs: set[frozenset[str]] = set()  # topics seen carrying the same stamps

    def start(self) -> None:
        """Subscribe to the log, parameter and diagnostics topics and start draining."""
        for topic, type_name in LOGS.items():
            self._subscribe(topic, type_name)
        self._subscribe("/diagnostics", DIAG_TYPE)
        # /clock may be discovered a sample or two after the topics stamped with its time
        self.clock.expect(time.time_ns() + FIRST_LOOK_NS)
        self._thread = threading.Thread(target=self._run, name="stream-viz-topics", daemon=True)
        self._thread.start()

    def update(self, topics: dict[str, list[str]], service_events: dict[str, str] | None = None,
               goal_status: Iterable[str] = (), goal_feedback: dict[str, str] | None = None) -> None:
        """Follow the graph: subscribe to new topics, drop vanished ones (keeps the event topics).

        ``topics``: topic → types (measured when ``metrics``; /diagnostics_agg always);
        ``service_events``: service → its event topic's type (service introspection);
        ``goal_status``: action servers' status topics (`stream_viz.collect.goals`);
        ``goal_feedback``: their feedback topics → type (counted only: when the newest came).
        """
        want = {t: types[0] for t, types in topics.items()
                if types and t not in NO_RAW and (self.metrics or t in DIAGNOSTICS)}
        want.update({s + EVENT_SUFFIX: ty for s, ty in (service_events or {}).items()})
        want.update(dict.fromkeys(goal_status, GOAL_STATUS_TYPE))
        want.update(goal_feedback or {})
        with self._lock:
            for t in list(self._watches):
                w = self._watches[t]
                keep = t in LOGS or t == "/diagnostics"
                if not keep and (t not in want or self._types.get(t) != want[t]):
                    self.node.destroy_subscription(w.sub)
                    del self._watches[t]
            for t in list(self._failed):
                if t not in want and t not in LOGS:
                    del self._failed[t]
        for t, type_name in want.items():
            if t in self._watches or (t in self._failed and self._types.get(t) == type_name):
                continue  # watched already, or known not to work for this type
            self._subscribe(t, type_name)

    def _subscribe(self, topic: str, type_name: str) -> None:
        self._types[topic] = type_name
        try:
            cls = import_type(type_name)
        except (ImportError, AttributeError, ValueError) as e:
            self._failed[topic] = f"message type {type_name} is not installed ({e.__class__.__name__})"
            return
        kind = ("log" if topic in LOGS else "diag" if topic in DIAGNOSTICS
                else "status" if topic.endswith(STATUS_SUFFIX) and type_name == GOAL_STATUS_TYPE
                else "event" if topic.endswith(EVENT_SUFFIX) and is_service_event(cls)
                else "clock" if topic == ROS_CLOCK and type_name == CLOCK_TYPE else "raw")
        try:
            sub = self.node.create_subscription(cls, topic, lambda _m: None,
                                                STATUS_QOS if kind == "status" else OBSERVE_QOS,
                                                raw=kind != "log")
        except Exception as e:  # rclpy raises plain RuntimeError/RCLError kinds; one topic must not stop us
            self._failed[topic] = f"cannot subscribe: {e}"
            return
        window = TopicWindow()
        now = time.time_ns()
        with self._lock:
            self._failed.pop(topic, None)
            self._watches[topic] = _Watch(sub, now, window, kind, has_header(cls),
                                          self._sink(topic, kind, window))
            if kind == "clock":  # drained first: the stamps taken after it are aged on its ticks
                self.clock.expect(now + CLOCK_GRACE_NS)
                self._watches = {topic: self._watches.pop(topic), **self._watches}

    def _sink(self, topic: str, kind: str, window: TopicWindow) -> Sink | None:
        """What to do with each message taken from ``topic``; None: its window's add (raw)."""
        add, clock = window.add, self.clock
        if kind == "clock":
            def tick(recv: int, src: int, size: int, seq: int, gid: bytes | None, head: bytes) -> None:
                clock.tick(recv, header_stamp_ns(head))  # a Clock begins with its time, as a Header
                add(recv, src, size, seq, gid)
            return tick
        if kind == "event":
            service, events = topic[: -len(EVENT_SUFFIX)], self._service_events

            def event(recv: int, src: int, size: int, seq: int, gid: bytes | None, head: bytes) -> None:
                info = service_event_info(head)
                if info is not None:
                    events.append((service, recv, info, gid))
            return event
        if kind in ("diag", "log", "status"):
            messages = self._messages

            def keep(recv: int, src: int, size: int, seq: int, gid: bytes | None, msg: Any) -> None:
                # diagnostics and goal status arrays come as bytes (deserialised later)
                stamp = header_stamp_ns(msg) if kind == "diag" else None
                add(recv, src, size, seq, gid, None if stamp is None else clock.age(recv, stamp))
                messages.append((topic, msg, recv, gid))
            return keep
        return None

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            self.drain()

    def drain(self) -> None:
        """Take every waiting message of every watched topic now; adapt the drain period."""
        peak = 0
        with self._lock:
            now, wall = time.monotonic(), time.time_ns()  # one clock read a drain, not one a topic
            elapsed, self._last_drain = now - self._last_drain, now
            for w in self._watches.values():
                try:
                    # The handle is held once per topic, not per message: the per-message cost
                    # is what topic metrics cost on a busy system.
                    handle = w.sub.handle
                    with handle:
                        taken = self._take(handle, w, wall)
                except Exception:  # a destroyed handle or a bad message: skip this topic this round
                    taken = 0
                self.taken += taken
                peak = max(peak, taken)
        if elapsed >= self.min_period_s:  # a drain right after another (`stats`) says nothing of rates
            self.period_s = drain_period(peak, elapsed, OBSERVE_QOS.depth, self.min_period_s,
                                         self.max_period_s)

    def _take(self, handle: Any, w: _Watch, wall: int) -> int:
        """Take what waits on one subscription: through rcl with gids, else through rclpy
        (``wall``: our time now, ns, for the message age's clock)."""
        rcl = self.rcl
        if rcl is not None and rcl.available and w.kind != "log":
            age = self.clock.aging(wall) if w.stamped else None
            n = rcl.drain(handle, w.window.add, age, w.sink, payload=w.kind in ("diag", "status"))
            if rcl.available:
                return n
        raw, take, msg_type, n = w.kind != "log", handle.take_message, w.sub.msg_type, 0
        add, sink, stamped, age = w.window.add, w.sink, w.stamped, self.clock.aging(wall)
        while (got := take(msg_type, raw)) is not None:
            msg, info = got
            n += 1
            recv, src, seq = info["received_timestamp"], info["source_timestamp"], info.get(
                "publication_sequence_number")
            size = len(msg) if raw else 0
            if sink is not None:
                sink(recv, src, size, seq, None, msg)
            elif stamped:
                stamp = header_stamp_ns(msg)
                add(recv, src, size, seq, None, None if stamp is None else age(recv, stamp))
            else:
                add(recv, src, size, seq)
        return n

    def take_messages(self) -> list[tuple[str, Any, int, bytes | None]]:
        """Return and forget the messages of the event topics taken so far, deserialised:
        ``(topic, message, received ns, publisher gid or None)``. A diagnostics message that
        cannot be deserialised is returned as its bytes."""
        with self._lock:  # the sinks hold the list: empty it, do not replace it
            out = self._messages[:]
            self._messages.clear()
            types = {t: w.sub.msg_type for t, w in self._watches.items() if w.kind in ("diag", "status")}
        for i, (topic, msg, recv, gid) in enumerate(out):
            if isinstance(msg, bytes) and topic in types:
                try:
                    out[i] = (topic, deserialize_message(msg, types[topic]), recv, gid)
                except Exception:  # a malformed message: the caller reports it
                    pass
        return out

    def take_service_events(self) -> list[tuple[str, int, tuple[int, int, bytes, int], bytes | None]]:
        """Return and forget the service events taken so far: ``(service, received ns,
        (event type, stamp ns, client gid, sequence number), publisher gid or None)``."""
        with self._lock:
            out = self._service_events[:]
            self._service_events.clear()
        return out

    def stats(self, publishers: dict[str, int]) -> dict[str, TopicStats]:
        """Return metrics per topic over the window; ``publishers`` (topic → count) gates drop counting."""
        self.drain()  # the thread drains rarely on a calm system: be up to date now
        now = time.time_ns()
        out: dict[str, TopicStats] = {t: TopicStats(False, why) for t, why in self._failed.items()}
        stamps: dict[str, list[int]] = {}
        with self._lock:
            for t, w in self._watches.items():
                if w.kind == "event":  # service events: not a topic of the model
                    continue
                w.window.expire(now - self.window_ns)
                m = w.window.metrics(now, w.created_ns, self.window_ns, publishers.get(t, 0),
                                     sized=w.kind != "log")
                gap = w.window.take_gap()
                if m and gap > 0:
                    m["gap_s"] = gap  # a quiet that began and ended between two samples
                if m and w.kind == "clock" and (pace := self.clock.pace(now, PACE_SPAN_NS)) is not None:
                    m["sim_pace"] = pace
                out[t] = TopicStats(True, "", m, w.window.publisher_rates(now, w.created_ns, self.window_ns),
                                    w.window.publisher_ages(), w.window.take_resets())
                if w.window.n_age:
                    stamps[t] = w.window.newest_stamps(COMPARED)
        for t, partners in stamp_partners(stamps, self._stamp_pairs).items():
            out[t].stamp_partners = partners
            self._stamp_pairs.update(frozenset((t, u)) for u, sh in partners.items() if sh >= PAIR_SHARE)
        if not self.metrics:
            for t in publishers:
                out.setdefault(t, TopicStats(False, "topic metrics are off"))
        return out

    def close(self) -> None:
        """Stop the thread (subscriptions go with the node)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        if self.rcl is not None and (self._thread is None or not self._thread.is_alive()):
            self.rcl.close()


def drain_period(peak: int, elapsed_s: float, depth: int, shortest: float, longest: float) -> float:
    """Return the time until the next drain: the fastest topic may fill a quarter of its queue.

    ``peak`` messages of one topic were taken after ``elapsed_s``; at that rate a quarter of
    ``depth`` arrives in the returned time, clipped to ``[shortest, longest]``.
    """
    if peak <= 0 or elapsed_s <= 0:
        return longest
    return min(longest, max(shortest, 0.25 * depth * elapsed_s / peak))


LOG_LEVELS = {30: "warn", 40: "error", 50: "fatal"}


def logger_node(logger: str, nodes: set[str] | frozenset[str]) -> str:
    """Return the node fqn a /rosout logger name belongs to (``ns.talker.child`` → ``/ns/talker``)."""
    parts = [p for p in logger.replace("/", ".").split(".") if p]
    for k in range(len(parts), 0, -1):
        cand = "/" + "/".join(parts[:k])
        if cand in nodes:
            return cand
    # Not a node we know (yet): the logger's own name, as a node would be called.
    return "/" + "/".join(parts) if parts else "/"


def log_event(msg: Any, nodes: set[str] | NodeNames, services: frozenset[str] = frozenset(),
              actions: frozenset[str] = frozenset()) -> Event | None:
    """Return a ``log`` Event for a /rosout message of level WARN or higher, else None.

    When the text names nodes, ``services`` or ``actions`` of the graph (`named_in_text`, relative
    names against the logging node's namespace), the event data lists them as member ids in
    ``nodes``, ``services`` and ``actions``: a client's "service /plan not available" or "action
    server compute_path_to_pose timed out" points at the server.
    """
    level = int(msg.level)
    if level < 30:
        return None
    index = nodes if isinstance(nodes, NodeNames) else NodeNames(nodes)
    sev = LOG_LEVELS.get(level, "fatal" if level > 50 else "warn")
    t = msg.stamp.sec + msg.stamp.nanosec * 1e-9
    node = logger_node(msg.name, index.fqns)
    data = {"logger": msg.name, "level": level, "file": msg.file, "function": msg.function,
            "line": int(msg.line)}
    named, called = named_in_text(msg.msg, index, services | actions, node.rsplit("/", 1)[0] or "/", node)
    if named:
        data["nodes"] = [f"node:{n}" for n in named]
    if srv := [f"service:{c}" for c in called if c in services]:
        data["services"] = srv
    if act := [f"action:{c}" for c in called if c in actions and c not in services]:
        data["actions"] = act
    return Event(t, "log", f"node:{node}", sev, msg.msg, data)
