"""Topic metrics from raw subscriptions drained without an executor, plus /rosout and /diagnostics.

A background thread takes every waiting message (``take_message`` on the handle; no callbacks,
no deserialisation) and keeps ``(received, source timestamp, size, sequence number)`` per topic
over a sliding window with running sums (`TopicWindow`). Inter-arrival times stay exact: they come from the
``received_timestamp`` DDS stamps, not from when we drained. ``/rosout`` and ``/diagnostics`` are
deserialised and turned into events. The QoS (best effort, volatile) matches any publisher.
"""

from __future__ import annotations

import importlib
import threading
import time
from dataclasses import dataclass
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from stream_viz.collect.readings import TopicStats
from stream_viz.collect.window import TopicWindow
from stream_viz.records import Event

OBSERVE_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT,
                         durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST)
NO_RAW = frozenset({"/rosout", "/parameter_events"})  # busy infrastructure topics: no metrics


def import_type(type_name: str) -> type:
    """Import a message class from ``pkg/msg/Name``; raises ImportError / AttributeError naming it."""
    pkg, _, name = type_name.rpartition("/")
    module = pkg.replace("/", ".")
    return getattr(importlib.import_module(module), name)


@dataclass
class _Watch:
    sub: Any
    created_ns: int
    window: TopicWindow
    deserialize: bool = False


class TopicMonitor:
    """Raw subscriptions on the observed topics and a thread that drains them.

    Parameters
    ----------
    node : rclpy Node
        Our observer node (only subscriptions are created on it; nothing is published).
    window_s : float
        Length of the sliding window metrics are computed over.
    metrics : bool
        Subscribe to every topic for metrics; False keeps only /rosout and /diagnostics.
    period_s : float
        Longest time between two drains of the thread. It drains more often when a topic is fast
        enough to fill a quarter of the queue (``OBSERVE_QOS.depth``) in that time; `stats` drains
        first, so the metrics are up to date whatever the period. Draining costs a wake-up per
        call: a calm system is drained rarely (the receive stamps are the middleware's, taken on
        arrival, so a late drain costs no accuracy; only the queue bounds the period).
    min_period_s : float
        Shortest time between two drains (a very fast topic).
    """

    def __init__(self, node: Node, window_s: float = 3.0, metrics: bool = True,
                 period_s: float = 1.0, min_period_s: float = 0.02) -> None:
        self.node, self.window_ns, self.metrics = node, int(window_s * 1e9), metrics
        self.max_period_s, self.min_period_s = period_s, min_period_s
        self.period_s = period_s  # the current one, adapted to the fastest topic
        self._last_drain = time.monotonic()
        self._lock = threading.Lock()
        self._watches: dict[str, _Watch] = {}
        self._failed: dict[str, str] = {}  # topic -> why it is not measured
        self._types: dict[str, str] = {}
        self._messages: list[tuple[str, Any, dict]] = []  # deserialised /rosout and /diagnostics
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.taken = 0  # messages taken so far (for the benchmark)

    def start(self) -> None:
        """Subscribe to /rosout and /diagnostics and start draining."""
        for topic, type_name in (("/rosout", "rcl_interfaces/msg/Log"),
                                 ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")):
            self._subscribe(topic, type_name, deserialize=True)
        self._thread = threading.Thread(target=self._run, name="stream-viz-topics", daemon=True)
        self._thread.start()

    def update(self, topics: dict[str, list[str]]) -> None:
        """Follow the graph: subscribe to new topics, drop vanished ones (keeps the two log topics)."""
        if not self.metrics:
            return
        want = {t: types[0] for t, types in topics.items() if types and t not in NO_RAW}
        with self._lock:
            for t in list(self._watches):
                w = self._watches[t]
                if not w.deserialize and (t not in want or self._types.get(t) != want[t]):
                    self.node.destroy_subscription(w.sub)
                    del self._watches[t]
            for t in list(self._failed):
                if t not in want:
                    del self._failed[t]
        for t, type_name in want.items():
            if t in self._watches or (t in self._failed and self._types.get(t) == type_name):
                continue  # watched already, or known not to work for this type
            self._subscribe(t, type_name)

    def _subscribe(self, topic: str, type_name: str, deserialize: bool = False) -> None:
        self._types[topic] = type_name
        try:
            cls = import_type(type_name)
        except (ImportError, AttributeError, ValueError) as e:
            self._failed[topic] = f"message type {type_name} is not installed ({e.__class__.__name__})"
            return
        try:
            sub = self.node.create_subscription(cls, topic, lambda _m: None, OBSERVE_QOS, raw=not deserialize)
        except Exception as e:  # rclpy raises plain RuntimeError/RCLError kinds; one topic must not stop us
            self._failed[topic] = f"cannot subscribe: {e}"
            return
        with self._lock:
            self._failed.pop(topic, None)
            self._watches[topic] = _Watch(sub, time.time_ns(), TopicWindow(), deserialize)

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            self.drain()

    def drain(self) -> None:
        """Take every waiting message of every watched topic now; adapt the drain period."""
        peak = 0
        with self._lock:
            now = time.monotonic()
            elapsed, self._last_drain = now - self._last_drain, now
            for topic, w in self._watches.items():
                raw = not w.deserialize
                handle, add, taken = w.sub.handle, w.window.add, 0
                try:
                    # The handle is held once per topic, not per message: the per-message cost
                    # is what topic metrics cost on a busy system.
                    with handle:
                        take, msg_type = handle.take_message, w.sub.msg_type
                        while (got := take(msg_type, raw)) is not None:
                            msg, info = got
                            taken += 1
                            add(info["received_timestamp"], info["source_timestamp"],
                                len(msg) if raw else 0, info.get("publication_sequence_number"))
                            if not raw:
                                self._messages.append((topic, msg, info))
                except Exception:  # a destroyed handle or a bad message: skip this topic this round
                    pass
                self.taken += taken
                peak = max(peak, taken)
        if elapsed >= self.min_period_s:  # a drain right after another (`stats`) says nothing of rates
            self.period_s = drain_period(peak, elapsed, OBSERVE_QOS.depth, self.min_period_s,
                                         self.max_period_s)

    def take_messages(self) -> list[tuple[str, Any, dict]]:
        """Return and forget the deserialised /rosout and /diagnostics messages taken so far."""
        with self._lock:
            out, self._messages = self._messages, []
        return out

    def stats(self, publishers: dict[str, int]) -> dict[str, TopicStats]:
        """Return metrics per topic over the window; ``publishers`` (topic → count) gates drop counting."""
        self.drain()  # the thread drains rarely on a calm system: be up to date now
        now = time.time_ns()
        out: dict[str, TopicStats] = {t: TopicStats(False, why) for t, why in self._failed.items()}
        with self._lock:
            for t, w in self._watches.items():
                w.window.expire(now - self.window_ns)
                m = w.window.metrics(now, w.created_ns, self.window_ns, publishers.get(t, 0),
                                     sized=not w.deserialize)
                out[t] = TopicStats(True, "", m)
        if not self.metrics:
            for t in publishers:
                out.setdefault(t, TopicStats(False, "topic metrics are off"))
        return out

    def close(self) -> None:
        """Stop the thread (subscriptions go with the node)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)


def drain_period(peak: int, elapsed_s: float, depth: int, shortest: float, longest: float) -> float:
    """Return the time until the next drain: the fastest topic may fill a quarter of its queue.

    ``peak`` messages of one topic were taken after ``elapsed_s``; at that rate a quarter of
    ``depth`` arrives in the returned time, clipped to ``[shortest, longest]``.
    """
    if peak <= 0 or elapsed_s <= 0:
        return longest
    return min(longest, max(shortest, 0.25 * depth * elapsed_s / peak))


LOG_LEVELS = {30: "warn", 40: "error", 50: "fatal"}
DIAG_LEVELS = {0: "info", 1: "warn", 2: "error", 3: "warn"}
DIAG_NAMES = {0: "OK", 1: "WARN", 2: "ERROR", 3: "STALE"}


def logger_node(logger: str, nodes: set[str]) -> str:
    """Return the node fqn a /rosout logger name belongs to (``ns.talker.child`` → ``/ns/talker``)."""
    parts = [p for p in logger.replace("/", ".").split(".") if p]
    for k in range(len(parts), 0, -1):
        cand = "/" + "/".join(parts[:k])
        if cand in nodes:
            return cand
    # Not a node we know (yet): the logger's own name, as a node would be called.
    return "/" + "/".join(parts) if parts else "/"


def log_event(msg: Any, nodes: set[str]) -> Event | None:
    """Return a ``log`` Event for a /rosout message of level WARN or higher, else None."""
    level = int(msg.level)
    if level < 30:
        return None
    sev = LOG_LEVELS.get(level, "fatal" if level > 50 else "warn")
    t = msg.stamp.sec + msg.stamp.nanosec * 1e-9
    node = logger_node(msg.name, nodes)
    return Event(t, "log", f"node:{node}", sev, msg.msg,
                 {"logger": msg.name, "level": level, "file": msg.file, "function": msg.function,
                  "line": int(msg.line)})


def diag_member(status: Any, publishers: list[str], nodes: set[str]) -> str:
    """Return the member a diagnostics status concerns: the only publisher, else a node it names."""
    if len(publishers) == 1:
        return f"node:{publishers[0]}"
    base = {n.rsplit("/", 1)[-1]: n for n in nodes}
    for text in (status.name, status.hardware_id):
        head = text.split(":", 1)[0].strip()
        for key in (head, "/" + head.lstrip("/")):
            if key in nodes:
                return f"node:{key}"
        if head in base:
            return f"node:{base[head]}"
    return "topic:/diagnostics"


def diag_events(msg: Any, t: float, publishers: list[str], nodes: set[str]) -> list[Event]:
    """Return one ``diag`` Event per status of a DiagnosticArray (OK ones at level info)."""
    out = []
    for st in msg.status:
        lvl = st.level
        lvl = lvl[0] if isinstance(lvl, bytes | bytearray) else int(lvl)
        out.append(Event(
            t, "diag", diag_member(st, publishers, nodes), DIAG_LEVELS.get(lvl, "warn"),
            f"{st.name}: {DIAG_NAMES.get(lvl, lvl)} {st.message}".strip(),
            {"name": st.name, "hardware_id": st.hardware_id, "level": lvl,
             "values": {kv.key: kv.value for kv in st.values}},
        ))
    return out
